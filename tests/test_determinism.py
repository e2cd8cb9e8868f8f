"""Same config and seed, byte-identical data files: wall-clock times live only in the documented
timing fields (``meta.json``'s ``wall_s`` and ``mitsuba_renders`` of ``render``; ``metrics.json``'s
``wall_s``, ``timings_s`` and ``mitsuba_renders`` and the report of ``reproduce``, tested in
``test_reproduce.py``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH

runner = CliRunner()

TINY = (
    f"base = '{DEFAULT_CONFIG_PATH}'\nlines = 8\n"
    "[sensor]\nrows = 12\ncolumns = 48\n[target]\npanel_lines = 96\npanel_columns = 48\n"
    "[render]\nspp = 4\n[fusion]\nmu1 = 2\nmu2 = 8\n"
)
#: fields that hold the run's own figures (wall-clock time, renders made), by file name
TIMING_FIELDS = {"meta.json": ("wall_s", "mitsuba_renders")}


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _without_timing(name: str, data: bytes) -> bytes:
    fields = TIMING_FIELDS.get(Path(name).name)
    if not fields:
        return data
    doc = json.loads(data)
    for f in fields:
        doc.pop(f, None)
    return json.dumps(doc, sort_keys=True).encode()


def _run_twice(tmp_path: Path, args: list[str], seeds: tuple[int, int] = (5, 5)) -> tuple[dict, dict]:
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY)
    out = []
    for k, seed in enumerate(seeds):
        folder = tmp_path / f"run{k}"
        a = [x.replace("{cfg}", str(cfg)).replace("{d}", str(tmp_path)) for x in args]
        r = runner.invoke(app, [*a, "--seed", str(seed), "--out", str(folder)])
        assert r.exit_code == 0, r.stderr
        out.append({n: _without_timing(n, b) for n, b in _files(folder).items()})
    return out[0], out[1]


CASES = {
    "render": ["render", "{cfg}", "--frames", "14"],
    "simulate zarr": ["simulate", "{cfg}", "--stages", "1,2,8", "--format", "zarr"],
    "simulate netcdf": ["simulate", "{cfg}", "--stages", "2,8", "--format", "netcdf"],
    "simulate tiff": ["simulate", "{cfg}", "--stages", "2,8", "--format", "tiff"],
}


@pytest.mark.parametrize("args", list(CASES.values()), ids=list(CASES))
def test_same_seed_gives_byte_identical_files(tmp_path: Path, args: list[str]) -> None:
    a, b = _run_twice(tmp_path, args)
    assert len(a) >= 2 and set(a) == set(b)
    differ = [n for n in a if a[n] != b[n]]
    assert differ == [], differ


def test_another_seed_changes_the_data(tmp_path: Path) -> None:
    """The comparison above can fail: a different seed changes the stage images."""
    import tifffile

    _run_twice(tmp_path, CASES["simulate tiff"], seeds=(5, 6))
    dn, refl = ([tifffile.imread(tmp_path / f"run{k}" / f"stage_002_{v}.tiff") for k in (0, 1)]
                for v in ("dn", "reflectance"))
    assert not np.array_equal(*dn)
    assert np.array_equal(*refl)  # the paper target is not random


def test_fuse_is_byte_identical(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    np.save(tmp_path / "low.npy", rng.integers(0, 4096, (9, 11)).astype(np.uint16))
    np.save(tmp_path / "high.npy", rng.integers(0, 4096, (9, 11)).astype(np.uint16))
    outs = []
    for _ in range(2):
        r = runner.invoke(app, ["fuse", str(tmp_path / "low.npy"), str(tmp_path / "high.npy"),
                                "--out", str(tmp_path / "h.exr"), "--tra", str(tmp_path / "t.png")])
        assert r.exit_code == 0, r.stderr
        outs.append(((tmp_path / "h.exr").read_bytes(), (tmp_path / "t.png").read_bytes()))
    assert outs[0] == outs[1]


def test_ptc_is_byte_identical_figures_included(tmp_path: Path) -> None:
    from bench_sim.config import load_config
    from bench_sim.workflows.ptc_job import run_ptc

    cfg = load_config(DEFAULT_CONFIG_PATH)
    runs = []
    for name in ("a", "b"):
        run_ptc(cfg, [1, 3], 9, tmp_path / name, lines=8, columns=16, dense_levels=3, spatial_images=3)
        runs.append(_files(tmp_path / name))
    assert len(runs[0]) > 100 and any(n.endswith(".png") for n in runs[0])
    assert [n for n in runs[0] if runs[0][n] != runs[1].get(n)] == []
