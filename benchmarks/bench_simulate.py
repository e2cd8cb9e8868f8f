"""Cost of ``bench-sim simulate`` with every stage (streamed to its Zarr store) against stages
{10, 80}, its peak memory at two numbers of lines, and both against a baseline revision.

1. Time: ``bench-sim simulate --stages all`` and ``--stages 10,80`` (truth included) on the paper
   rig at 256 lines x 256 columns, wall time of the whole command (start-up included), paired and
   interleaved runs (:func:`baseline.paired`) of this checkout and of the baseline revision
   (:data:`baseline.BASELINE_REV`, ``--baseline``). Prints the medians and the ratio
   all / {10, 80} per side (target <= 2) and this checkout / baseline per stage set.
2. Memory: the peak resident set (``ru_maxrss`` of the command's own process, Mitsuba included)
   of ``--stages all`` at two line counts (``--lines-a``, ``--lines-b``): flat in the number of
   lines when the stages stream to disk (target: growth per line ~0).

Every command runs in a temporary folder: run from the repository root, ``python -m`` and
``python -c`` would put this checkout's package first on the path whatever the side's
``PYTHONPATH``.

Usage: python benchmarks/bench_simulate.py [--repeat 3] [--lines-a 256] [--lines-b 1024]
[--columns 256] [--baseline REV | --no-baseline] [--skip-time] [--skip-memory]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from baseline import ROOT, Side, add_baseline_args, load_line, median, paired

STAGE_SETS = {"all": "all", "{10, 80}": "10,80"}

_RSS_SCRIPT = """
import resource, runpy, sys
sys.argv = ["bench-sim", *sys.argv[1:]]
try:
    runpy.run_module("bench_sim", run_name="__main__")
except SystemExit as exc:
    if exc.code:
        raise
print("MAXRSS_KIB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _config(folder: Path, lines: int, columns: int) -> Path:
    """A TOML of the paper rig at ``lines`` x ``columns`` (its target panel as large)."""
    path = folder / f"bench_{lines}x{columns}.toml"
    base = ROOT / "bench_sim" / "scenes" / "paper_rig.toml"
    path.write_text(
        f'base = "{base}"\nlines = {lines}\n[sensor]\ncolumns = {columns}\n'
        f"[target]\npanel_lines = {min(lines, 1024)}\npanel_columns = {columns}\n"
    )
    return path


def _simulate_args(cfg: Path, stages: str, out: Path) -> list[str]:
    return ["simulate", str(cfg), "--stages", stages, "--seed", "0", "--out", str(out), "--format", "zarr"]


def _peak_rss_mib(side: Side, cfg: Path, stages: str, out: Path) -> float:
    """Peak resident set [MiB] of one ``bench-sim simulate`` process of ``side``."""
    done = subprocess.run([sys.executable, "-c", _RSS_SCRIPT, *_simulate_args(cfg, stages, out)],
                          env=side.env(), capture_output=True, text=True, cwd=out.parent)
    if done.returncode != 0:
        raise RuntimeError(f"simulate ({side.name}) exited {done.returncode}: {done.stderr[-2000:]}")
    line = [t for t in done.stdout.splitlines() if t.startswith("MAXRSS_KIB")][-1]
    return int(line.split()[1]) / 1024


def _times(sides: list[Side], cfg: Path, tmp: Path, repeat: int) -> None:
    print(f"time: simulate at {cfg.stem.removeprefix('bench_')} (lines x columns), {repeat} paired runs, "
          f"wall [s] of the whole command")
    med: dict[tuple[str, str], float] = {}
    for label, stages in STAGE_SETS.items():
        def run(side: Side, i: int, stages: str = stages) -> tuple[float, float]:
            out = tmp / f"t_{abs(hash(side.name))}_{stages.replace(',', '_')}_{i}"
            return side.bench_sim(*_simulate_args(cfg, stages, out), cwd=tmp)

        got = paired(sides, run, repeat)
        for side in sides:
            walls = [w for w, _ in got[side.name]]
            med[(side.name, label)] = median(walls)
            print(f"  {side.name:<22} stages {label:<9} median {median(walls):7.2f} s  "
                  f"(runs {', '.join(f'{w:.2f}' for w in walls)})")
    for side in sides:
        ratio = med[(side.name, "all")] / med[(side.name, "{10, 80}")]
        print(f"  {side.name:<22} all / {{10, 80}} = {ratio:.2f} (target <= 2)")
    if len(sides) == 2:
        for label in STAGE_SETS:
            ratio = med[(sides[0].name, label)] / med[(sides[1].name, label)]
            print(f"  stages {label:<9} {sides[0].name} / {sides[1].name} = {ratio:.2f}")


def _memory(sides: list[Side], tmp: Path, lines: tuple[int, int], columns: int) -> None:
    print(f"memory: peak RSS of simulate --stages all at {columns} columns")
    for side in sides:
        peaks = []
        for n in lines:
            cfg = _config(tmp, n, columns)
            peaks.append(_peak_rss_mib(side, cfg, "all", tmp / f"m_{abs(hash(side.name))}_{n}"))
            print(f"  {side.name:<22} {n:6d} lines: peak {peaks[-1]:8.1f} MiB")
        growth = (peaks[1] - peaks[0]) * 1024 / (lines[1] - lines[0])
        print(f"  {side.name:<22} growth {growth:.1f} KiB per line (flat: ~0)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--lines-a", type=int, default=256)
    ap.add_argument("--lines-b", type=int, default=1024)
    ap.add_argument("--columns", type=int, default=256)
    ap.add_argument("--skip-time", action="store_true")
    ap.add_argument("--skip-memory", action="store_true")
    add_baseline_args(ap)
    a = ap.parse_args()
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    print(load_line())
    with tempfile.TemporaryDirectory(prefix="bench_simulate_") as name:
        tmp = Path(name)
        if not a.skip_time:
            _times(sides, _config(tmp, 256, a.columns), tmp, a.repeat)
        if not a.skip_memory:
            _memory(sides, tmp, (a.lines_a, a.lines_b), a.columns)
    print(load_line())


if __name__ == "__main__":
    main()
