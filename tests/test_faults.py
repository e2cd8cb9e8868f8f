"""Fault injection in real processes: a write that fails with ENOSPC halfway through a set, Ctrl-C
(SIGINT), SIGTERM and SIGKILL at several points of a run. Whatever happens, the output folder
holds the previous complete set or a complete new one, never a mix; a rerun succeeds and leaves
no temporaries.

How the faults are made: ``BENCH_SIM_FAULT=KIND@POINT`` (:mod:`bench_sim.io`) makes the child
fail at a chosen point, deterministically and on any machine: ``N`` is the N-th file of the
output set, after its temporary file is written and before it is renamed, ``commit`` the set
complete but not yet renamed into place; ``enospc`` raises ``OSError(ENOSPC)`` there (no disk is
filled), the signal kinds make the process signal itself (a real signal, delivered by the
kernel). Two more faults come from outside, with no hook at all: ``RLIMIT_FSIZE`` makes the
kernel fail a write of the C EXR writer with ``EFBIG``, and the parent sends SIGINT or SIGKILL
while the child computes.
"""

from __future__ import annotations

import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH
from bench_sim.io import OUTPUT_MARKER

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "bench_sim"]
runner = CliRunner()

TINY = (
    f"base = '{DEFAULT_CONFIG_PATH}'\n"
    "[sensor]\nrows = 12\ncolumns = 48\n[target]\npanel_lines = 96\npanel_columns = 48\n"
    "[render]\nspp = 4\n[fusion]\nmu1 = 2\nmu2 = 8\n"
)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if ".partial-" in p.name or ".old-" in p.name)


def _child(args: list[str], env: dict[str, str] | None = None, **kw: object) -> subprocess.Popen:
    full = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    full.pop("BENCH_SIM_DEBUG", None)
    return subprocess.Popen(
        [*CLI, *args], cwd=ROOT, env=full, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw
    )


def _finish(proc: subprocess.Popen, timeout: float = 120) -> tuple[int, str]:
    _, err = proc.communicate(timeout=timeout)
    return proc.returncode, err


@pytest.fixture
def render_set(tmp_path: Path) -> tuple[Path, list[str], dict[str, bytes]]:
    """A complete render set (seed 1) in ``tmp_path/out`` and the arguments of a run with seed 2."""
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY)
    out = tmp_path / "out"
    args = ["render", str(cfg), "--frames", "20", "--out", str(out)]
    r = runner.invoke(app, [*args, "--seed", "1"])
    assert r.exit_code == 0, r.stderr
    return out, [*args, "--seed", "2"], _tree(out)


def _same_set_apart_from_timing(a: dict[str, bytes], b: dict[str, bytes]) -> bool:
    if set(a) != set(b):
        return False
    for name in a:
        if name == "meta.json":
            ma, mb = json.loads(a[name]), json.loads(b[name])
            ma.pop("wall_s"), mb.pop("wall_s")
            if ma != mb:
                return False
        elif a[name] != b[name]:
            return False
    return True


FAULTS = [
    # (fault, exit status, the line on stderr, temporaries left for the next run to remove)
    ("enospc@2", 2, "cannot write the output ground_truth.exr: No space left on device (ENOSPC)", False),
    ("sigint@1", 130, "bench-sim: interrupted: stopped by Ctrl-C", False),
    ("sigterm@2", 143, "bench-sim: terminated: stopped by SIGTERM", False),
    ("sigkill@2", -signal.SIGKILL, "", True),
    ("sigkill@commit", -signal.SIGKILL, "", True),
]


@pytest.mark.parametrize(("fault", "status", "line", "leftovers"), FAULTS, ids=[f[0] for f in FAULTS])
def test_a_fault_leaves_the_previous_set_and_a_rerun_succeeds(
    render_set: tuple[Path, list[str], dict[str, bytes]], fault: str, status: int, line: str, leftovers: bool
) -> None:
    out, args, before = render_set
    code, err = _finish(_child(args, {"BENCH_SIM_FAULT": fault}))
    assert code == status, err[-2000:]
    if line:
        assert err.count("\n") == 1 and err.startswith("bench-sim: ") and line in err, err
        assert "Traceback" not in err
    else:
        assert err == ""  # SIGKILL: the process could say nothing
    assert _tree(out) == before, "the previous complete set changed"
    assert bool(_temporaries(out.parent)) == leftovers
    # the rerun removes what a killed run left and writes the new set whole
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.stderr
    assert _temporaries(out.parent) == []
    assert json.loads((out / OUTPUT_MARKER).read_text())["seed"] == 2
    assert set(_tree(out)) == set(before)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_a_signal_from_outside_while_computing(
    render_set: tuple[Path, list[str], dict[str, bytes]], sig: int
) -> None:
    """The parent signals the child while it renders 1,000 frames; wherever it lands (an import,
    the render, a write), ``out`` holds one complete set: the previous one, or the new one if
    the signal came after it was in place."""
    out, args, before = render_set
    args = [a if a != "20" else "1000" for a in args]
    proc = _child(args)
    time.sleep(2.0)
    proc.send_signal(sig)
    code, err = _finish(proc)
    assert code in (130, -sig, 0), err[-2000:]
    if code == 130:
        assert err.startswith("bench-sim: interrupted: ") and err.count("\n") == 1, err
    record = json.loads((out / OUTPUT_MARKER).read_text())
    if record["seed"] == 1:  # the previous set, untouched
        assert _tree(out) == before
    else:  # the signal came after the new set was in place
        assert record["seed"] == 2 and set(_tree(out)) == set(before)
    if sig == signal.SIGINT:
        assert _temporaries(out.parent) == []
    r = runner.invoke(app, args)
    assert r.exit_code == 0 and _temporaries(out.parent) == []


def test_a_real_file_size_limit_during_the_exr_write(
    render_set: tuple[Path, list[str], dict[str, bytes]],
) -> None:
    """``RLIMIT_FSIZE`` (``ulimit -f``): the kernel fails the C EXR writer's write with EFBIG."""
    out, args, before = render_set

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (3000, resource.RLIM_INFINITY))

    code, err = _finish(_child(args, preexec_fn=limit))
    assert code == 2 and err.count("\n") == 1 and "cannot write the output" in err, err
    assert 'image file "exposures.exr". File too large' in err
    assert _tree(out) == before and _temporaries(out.parent) == []


def test_enospc_while_fusing_leaves_neither_file(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    np.save(tmp_path / "low.npy", rng.integers(0, 4096, (16, 16)).astype(np.uint16))
    np.save(tmp_path / "high.npy", rng.integers(0, 4096, (16, 16)).astype(np.uint16))
    args = ["fuse", str(tmp_path / "low.npy"), str(tmp_path / "high.npy"), "--out", str(tmp_path / "h.exr"),
            "--tra", str(tmp_path / "t.png")]
    code, err = _finish(_child(args, {"BENCH_SIM_FAULT": "enospc@2"}))
    assert code == 2 and err.count("\n") == 1, err
    assert f"--tra = '{tmp_path / 't.png'}': cannot write the output t.png: No space left on device" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["high.npy", "low.npy"]


def test_enospc_during_reproduce(tmp_path: Path) -> None:
    """The issue's case: disk full while ``reproduce`` writes its nine files; nothing is left."""
    (tmp_path / "tiny.toml").write_text(TINY)
    cfg = tmp_path / "r.toml"
    cfg.write_text("base = 'tiny.toml'\nlines = 200\n[target]\npanel_lines = 128\n")
    out = tmp_path / "paper"
    proc = _child(["reproduce", str(cfg), "--out", str(out)], {"BENCH_SIM_FAULT": "enospc@4"})
    code, err = _finish(proc, 300)
    assert code == 2 and err.count("\n") == 1 and err.startswith("bench-sim: error: "), err[-2000:]
    # the image files are written on a thread pool, so the fourth file written is one of them
    assert re.search(r"cannot write the output (gamma1\.tiff|gamma2\.tiff|gamma_hdr\.exr|gamma_tra\.png|"
                     r"fig3_stages\.png): No space left on device", err), err
    assert "Traceback" not in err
    assert not out.exists() and _temporaries(tmp_path) == []
