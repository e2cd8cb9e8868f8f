"""Up-front resource estimates against measured peaks: estimate / measured for a few runs.

Each run is a ``bench-sim`` command in a child process; its peak resident memory is the
child's ``ru_maxrss`` (``os.wait4``) and its output size the bytes under ``--out``. The
estimates (:mod:`bench_sim.workflows.estimates`) should be upper bounds within about 2.5x: a ratio below 1
means a run could be let through that does not fit, far above 2.5 that a run could be refused
that would.

Run: ``.venv/bin/python benchmarks/bench_resources.py`` (a few minutes on two cores).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench_sim.config import DEFAULT_CONFIG_PATH, load_config, quick_config
from bench_sim.io import format_bytes
from bench_sim.measure.ptc import plan_ptc
from bench_sim.workflows.estimates import (
    estimate_fuse,
    estimate_ptc,
    estimate_render,
    estimate_reproduce,
    estimate_simulate,
)
from bench_sim.workflows.reproduce.run import FIG3_STAGES

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "bench_sim"]


def _run(args: list[str], out: Path) -> tuple[int, int, float]:
    """(peak RSS bytes, output bytes, exit status) of one command in a child."""
    proc = subprocess.Popen([*CLI, *args], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"{args}: exit {proc.returncode}: {err[-500:]}")
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file()) if out.is_dir() else (
        out.stat().st_size if out.exists() else 0
    )
    return usage.ru_maxrss * 1024, size, proc.returncode


def _toml(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(f"base = '{DEFAULT_CONFIG_PATH}'\n{text}")
    return path


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        default = load_config()
        cases = []
        for frames in (8, 400):
            out = folder / f"r{frames}"
            cases.append((
                f"render default rig, {frames} frames",
                ["render", str(DEFAULT_CONFIG_PATH), "--frames", str(frames), "--out", str(out)],
                estimate_render(default, frames),
                folder / f"r{frames}",
            ))
        for lines in (128, 1024):
            cfg_path = _toml(folder, f"s{lines}.toml", f"lines = {lines}\n")
            cfg = load_config(cfg_path)
            cases.append((
                f"simulate default rig, {lines} lines, stages 10,80",
                ["simulate", str(cfg_path), "--stages", "10,80", "--out", str(folder / f"s{lines}")],
                estimate_simulate(cfg, (10, 80)),
                folder / f"s{lines}",
            ))
        q = quick_config(default)
        st = sorted(set(FIG3_STAGES) | {q.fusion.mu1, q.fusion.mu2})
        cases.append((
            "reproduce --quick", ["reproduce", "--quick", "--out", str(folder / "rq")],
            estimate_reproduce(q, st), folder / "rq",
        ))
        plan = plan_ptc(default, [1, 10, 80])
        cases.append((
            "ptc stages 1,10,80", ["ptc", "--stages", "1,10,80", "--out", str(folder / "p")],
            estimate_ptc(plan.stages, plan.levels.size, plan.lines, plan.columns, plan.spatial_images),
            folder / "p",
        ))
        rng = np.random.default_rng(0)
        shape = (2048, 2048)
        np.save(folder / "low.npy", rng.integers(0, 4096, shape).astype(np.uint16))
        np.save(folder / "high.npy", rng.integers(0, 4096, shape).astype(np.uint16))
        cases.append((
            f"fuse {shape[0]} x {shape[1]}",
            ["fuse", str(folder / "low.npy"), str(folder / "high.npy"), "--out", str(folder / "h.exr"),
             "--tra", str(folder / "h.png")],
            estimate_fuse(shape, True), folder / "h.exr",
        ))
        for name, args, est, out in cases:
            peak, size, _ = _run(args, out)
            if name.startswith("fuse"):
                size += (folder / "h.png").stat().st_size
            rows.append((name, est.memory_total, peak, est.disk_total, size))
    print(f"{'run':<46} {'memory est.':>12} {'measured':>10} {'ratio':>6}   {'disk est.':>10} "
          f"{'written':>10} {'ratio':>6}")
    for name, me, mm, de, dm in rows:
        print(f"{name:<46} {format_bytes(me):>12} {format_bytes(mm):>10} {me / mm:6.2f}   "
              f"{format_bytes(de):>10} {format_bytes(dm):>10} {de / max(dm, 1):6.2f}")


if __name__ == "__main__":
    main()
