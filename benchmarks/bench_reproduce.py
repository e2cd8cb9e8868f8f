"""Wall time of ``bench-sim reproduce`` per step against the targets, and its peak memory at two
line counts.

1. The default full run (1024 lines x 1024 columns, M = 100) and the ``--quick`` preset, each in
   this process (the first run also pays the imports and the Mitsuba/Dr.Jit start-up, as a user's
   run does): the time of every step, the total against the targets (8 s full, 2.5 s quick) and
   the CPU time (all threads) over the wall time. ``render_frames`` and ``sensor_dtdi`` are busy
   times that overlap on the thread pool; ``pass_wall`` is the wall time of the pass they share.
2. Peak resident memory (``VmHWM`` of a fresh process running the ``bench-sim reproduce``
   command; Linux) at 1,024 and 4,096 lines (256 columns, ``target.panel_columns = 256``), and the ratio
   (target: at most 1.2).

Usage: python benchmarks/bench_reproduce.py [--skip-full] [--skip-memory]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_sim.config import DEFAULT_CONFIG_PATH, load_config
from bench_sim.runtime.parallel import thread_count
from bench_sim.workflows.reproduce.run import run_reproduce

TARGET_S = {"full": 8.0, "quick": 2.5}
MEMORY_LINES = (1024, 4096)
MEMORY_COLUMNS = 256


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _run(quick: bool) -> tuple[dict, float]:
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        c0 = _cpu_s()
        m = run_reproduce(load_config(), seed=0, out=Path(tmp), quick=quick)
        return m, _cpu_s() - c0


#: run in the child: the command, then its own peak RSS (VmHWM, kB) into $BENCH_PEAK_FILE
_CHILD = """
import atexit, os
def _peak():
    status = open("/proc/self/status").read().split("VmHWM:")[1].split()[0]
    open(os.environ["BENCH_PEAK_FILE"], "w").write(status)
atexit.register(_peak)
from bench_sim.cli import app
app()
"""


def peak_rss_mib(lines: int, columns: int) -> tuple[float, float]:
    """(peak resident memory [MiB], wall [s]) of ``bench-sim reproduce`` in a fresh process: the
    process's own high-water mark (``VmHWM``; a child's ``ru_maxrss`` would include its parent's
    memory at the fork)."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "bench.toml"
        cfg.write_text(
            f'base = "{DEFAULT_CONFIG_PATH}"\nlines = {lines}\n[sensor]\ncolumns = {columns}\n'
            f"[target]\npanel_columns = {columns}\n"
        )
        peak_file = Path(tmp) / "peak_kb"
        cmd = [sys.executable, "-c", _CHILD, "reproduce", str(cfg), "--out", str(Path(tmp) / "out")]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       env={**os.environ, "BENCH_PEAK_FILE": str(peak_file)})
        return int(peak_file.read_text()) / 1024.0, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--skip-memory", action="store_true")
    a = ap.parse_args()
    print(f"threads: {thread_count()} (BENCH_SIM_THREADS or the usable cores)")
    runs = [("full", False)] if not a.skip_full else []
    runs.append(("quick", True))
    for name, quick in runs:
        m, cpu = _run(quick)
        pixel_frames = m["frames"] * m["rows"] * m["columns"]  # every sensor pixel of every frame
        print(f"{name}: {m['lines']} lines x {m['columns']} columns, M = {m['rows']}, "
              f"{m['frames']} frames, {len(m['stages'])} stages")
        for step, s in m["timings_s"].items():
            print(f"  {step:<14} {s:7.2f} s")
        target = TARGET_S[name]
        wall = m["wall_s"]
        print(f"  {'total':<14} {wall:7.2f} s  = {wall / target:.2f} x the {target:g} s target; "
              f"CPU {cpu:.1f} s ({100 * cpu / m['wall_s']:.0f} % of the wall time); "
              f"{pixel_frames / m['wall_s'] / 1e6:.1f} M sensor pixel-frames/s end to end")
    if not a.skip_memory:
        peaks = {n: peak_rss_mib(n, MEMORY_COLUMNS) for n in MEMORY_LINES}
        for n, (mib, wall) in peaks.items():
            print(f"peak RSS, {n} lines x {MEMORY_COLUMNS} columns: {mib:7.1f} MiB ({wall:.1f} s)")
        lo, hi = (peaks[n][0] for n in MEMORY_LINES)
        print(f"ratio {MEMORY_LINES[1]} / {MEMORY_LINES[0]} lines: {hi / lo:.2f} (target: at most 1.2)")


if __name__ == "__main__":
    main()
