"""Every bound checked before any work (issue 32), each audit finding as its reproduction:

- ``reproduce --seeds``: the seed rule on the last seed ``seed + seeds - 1`` (``--seed 2**63-1
  --seeds 2`` ran seed 2**63), a cap on the count with a time estimate (``--seeds 2000000000``
  and ``20000000000000000000`` started without a word);
- JSON written strictly (no ``NaN`` token, whatever the value);
- an empty config runs the default and says so;
- a dataset glob over the whole file system is refused within seconds (it walked for minutes).

The other findings are tested where their command is: image headers and special files in
``tests/io/test_image_header.py`` and ``tests/test_bad_inputs.py``, calibrate's plausibility in
``tests/workflows/test_calibrate.py``, ``init`` in ``tests/workflows/test_config_cmd.py``, a
damaged dataset chunk in ``tests/workflows/test_dataset_loaders.py``, signals in
``tests/test_signals.py``.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH, load_config, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.io import write_json
from bench_sim.io.glob_walk import bounded_glob, glob_folders
from bench_sim.io.strict_json import strict_dumps
from bench_sim.workflows.reproduce.seeds import LONG_RUN_S, MAX_SEEDS, check_seeds, seconds_per_seed

runner = CliRunner()


def _one_error(res) -> str:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("bench-sim: error: "), res.stderr
    return lines[0]


# --- reproduce --seeds --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--seeds", "2000000000"], ["--seeds = 2000000000", f"more than {MAX_SEEDS} seeds", "years in all"]),
        (["--seeds", "20000000000000000000"], ["--seeds = 20000000000000000000", "years in all"]),
        (["--seed", str(2**63 - 1), "--seeds", "2"], [f"the last seed, {2**63}", "0..2**63-1",
                                                      f"--seed <= {2**63 - 2}"]),
        (["--seed", str(2**63 - 10), "--seeds", "11"], [f"the last seed, {2**63}"]),
    ],
    ids=["2e9 seeds", "2e19 seeds", "seed 2**63-1 + 2", "seed 2**63-10 + 11"],
)
def test_reproduce_seeds_are_refused_before_any_work(
    tmp_path: Path, args: list[str], needles: list[str]
) -> None:
    t0 = time.perf_counter()
    res = runner.invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / "out"), *args])
    line = _one_error(res)
    for needle in needles:
        assert needle in line, line
    assert time.perf_counter() - t0 < 10 and not (tmp_path / "out").exists()


def test_the_seed_time_estimate_scales_with_the_pass_and_warns_a_long_run() -> None:
    cfg = load_config(DEFAULT_CONFIG_PATH)
    stages = [1, 10, 80]
    wide = with_overrides(cfg, {"sensor": {"columns": 2 * cfg.sensor.columns},
                                "target": {"panel_columns": 2 * cfg.target.panel_columns}})
    assert seconds_per_seed(wide, stages) == pytest.approx(2 * seconds_per_seed(cfg, stages))
    each = seconds_per_seed(cfg, stages)
    short = max(2, int(LONG_RUN_S / each / 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_seeds(0, short, cfg, stages) == short  # no warning
    long = min(MAX_SEEDS, int(LONG_RUN_S / each) + 2)
    with pytest.warns(UserWarning, match=rf"--seeds = {long}: about .* for the {long - 1} further seeds"):
        check_seeds(0, long, cfg, stages)
    with pytest.raises(BenchSimError, match="must be an integer >= 1"):
        check_seeds(0, 0, cfg, stages)


# --- strict JSON ----------------------------------------------------------------------------------


def test_every_json_is_strict_whatever_the_values(tmp_path: Path) -> None:
    rng = np.random.default_rng(32)
    specials = [math.nan, math.inf, -math.inf, np.float32("nan"), np.float64("inf")]
    value = {
        "scalars": [specials[i] for i in rng.integers(0, len(specials), 20)],
        "array": np.where(rng.random((3, 4)) < 0.5, np.nan, rng.random((3, 4))),
        "nested": {"t": (np.int64(3), np.float32(1.5), Path("/x")), "deep": [[{"v": math.nan}]]},
    }

    def refuse(token: str) -> None:
        raise ValueError(token)

    back = json.loads(strict_dumps(value), parse_constant=refuse)
    assert back["nested"]["deep"][0][0]["v"] is None and back["nested"]["t"] == [3, 1.5, "/x"]
    assert all(v is None for v in back["scalars"])
    arr = back["array"]
    assert [[v is None for v in row] for row in arr] == np.isnan(value["array"]).tolist()
    write_json(tmp_path / "a.json", value)
    assert json.loads((tmp_path / "a.json").read_text(), parse_constant=refuse) == back


# --- an empty config --------------------------------------------------------------------------------


@pytest.mark.parametrize("text", ["", "# only a comment\n\n"])
def test_an_empty_config_says_it_runs_the_default(tmp_path: Path, text: str) -> None:
    empty = tmp_path / "empty.toml"
    empty.write_text(text)
    res = runner.invoke(app, ["config", "show", str(empty)])
    assert res.exit_code == 0, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and "empty.toml: no settings (an empty file)" in lines[0], lines
    assert "paper rig" in lines[0] and lines[0].startswith("bench-sim: warning: ")
    assert runner.invoke(app, ["config", "show", str(DEFAULT_CONFIG_PATH)]).stderr == ""


# --- a glob's walk ----------------------------------------------------------------------------------


def test_a_glob_counts_the_folders_it_would_list(tmp_path: Path) -> None:
    for d in ("a/x", "a/y/z", "b"):
        (tmp_path / d).mkdir(parents=True)
    (tmp_path / "a" / "y" / "z" / "t.png").write_bytes(b"")
    assert glob_folders(str(tmp_path / "*.png"))[0] == 1  # the fixed folder alone
    assert glob_folders(str(tmp_path / "*" / "*.png"))[0] == 3  # it and a, b
    assert glob_folders(str(tmp_path / "**" / "*.png"))[0] == 6  # every folder
    assert bounded_glob(str(tmp_path / "**" / "*.png"), "p", limit=6) == [str(tmp_path / "a/y/z/t.png")]
    with pytest.raises(BenchSimError, match=rf"p: the pattern walks more than 5 folders below {tmp_path}"):
        bounded_glob(str(tmp_path / "**" / "*.png"), "p", limit=5)


def test_a_dataset_glob_over_the_whole_file_system_is_refused_in_seconds(tmp_path: Path) -> None:
    spec = tmp_path / "d.toml"
    spec.write_text(f'base = "{DEFAULT_CONFIG_PATH}"\nsamples = 2\nseed = 1\nstages = [2, 8]\n'
                    '[randomize]\n"target.image" = { dist = "glob", pattern = "/**/*.png" }\n')
    t0 = time.perf_counter()
    res = runner.invoke(app, ["dataset", str(spec), "--out", str(tmp_path / "o"), "--workers", "0"])
    line = _one_error(res)
    assert "randomize.target.image.pattern = '/**/*.png': the pattern walks more than" in line
    assert time.perf_counter() - t0 < 30 and not (tmp_path / "o").exists()
