"""The whole default ``bench-sim reproduce`` command, timed from outside, against the baseline.

1. A/B (issue 26): whole ``python -m bench_sim reproduce`` processes (default config and seed,
   imports, Mitsuba/Dr.Jit start-up and the files included) of this checkout and of the baseline
   revision (:data:`baseline.BASELINE_REV` unless ``--baseline``), paired and interleaved
   (:func:`baseline.paired`). Per side: the median wall time, the median CPU time (user +
   system of the process and its children) and their ratio (how much of the second core the run
   uses); the ratio of the medians to the baseline's; the load average before and after. The
   verdict is computed from those numbers: on an idle machine the target is a median wall time
   of at most :data:`TARGET_WALL_S` with CPU / wall at least :data:`TARGET_CPU_PER_WALL`; on a
   busy one (a 1-minute load average at the start of :data:`IDLE_LOAD` per CPU or more) at
   most :data:`TARGET_RATIO` times the baseline's wall time in the paired runs.
2. ``--memory``: peak resident memory (``VmHWM`` of a fresh ``bench-sim reproduce`` process;
   Linux) at 1,024 and 4,096 lines (256 columns), and their ratio (target: at most 1.2).

Usage: python benchmarks/bench_reproduce.py [--repeat N] [--baseline REV | --no-baseline] [--memory]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from baseline import Side, add_baseline_args, load_line, median, paired

from bench_sim.config import DEFAULT_CONFIG_PATH

#: the whole default command on an idle 2-core machine [s] (median wall time)
TARGET_WALL_S = 5.0
#: CPU time over wall time of the whole command, at least (the second core used)
TARGET_CPU_PER_WALL = 1.6
#: on a busy machine: this checkout's median wall time over the baseline's, at most
TARGET_RATIO = 0.75
#: 1-minute load average per CPU below which the machine counts as idle
IDLE_LOAD = 0.25
MEMORY_LINES = (1024, 4096)
MEMORY_COLUMNS = 256


def _idle() -> bool:
    return os.getloadavg()[0] < IDLE_LOAD * (os.cpu_count() or 1)


def ab(sides: list[Side], repeat: int) -> dict[str, list[tuple[float, float]]]:
    """``repeat`` paired runs of the whole default ``reproduce`` per side: (wall, CPU) [s]."""
    with tempfile.TemporaryDirectory() as tmp:

        def run(side: Side, i: int) -> tuple[float, float]:
            out = Path(tmp) / f"{i}-{side.name.replace(' ', '_')}"
            # cwd outside the checkout: ``python -m`` puts the working folder first on sys.path
            wall, cpu = side.bench_sim("reproduce", "--out", str(out), cwd=Path(tmp))
            print(f"  run {i + 1}, {side.name}: wall {wall:6.2f} s, CPU {cpu:6.2f} s", flush=True)
            return wall, cpu

        return paired(sides, run, repeat)


def report(times: dict[str, list[tuple[float, float]]], idle: bool) -> bool:
    """Print the medians, ratios and the verdict; returns whether the target is met."""
    med = {name: (median([w for w, _ in r]), median([c for _, c in r])) for name, r in times.items()}
    for name, (wall, cpu) in med.items():
        print(f"{name:<28} median wall {wall:7.2f} s, CPU {cpu:7.2f} s, CPU / wall {cpu / wall:.2f} "
              f"({len(times[name])} runs)")
    cur_wall, cur_cpu = med[Side.current().name]
    base = [v for k, v in med.items() if k != Side.current().name]
    ratio = cur_wall / base[0][0] if base else None
    if ratio is not None:
        print(f"this checkout / baseline: wall {ratio:.2f} x, CPU {cur_cpu / base[0][1]:.2f} x")
    meets_idle = cur_wall <= TARGET_WALL_S and cur_cpu / cur_wall >= TARGET_CPU_PER_WALL
    print(f"idle target (wall <= {TARGET_WALL_S:g} s and CPU / wall >= {TARGET_CPU_PER_WALL:g}): "
          f"{'met' if meets_idle else 'not met'} (wall {cur_wall:.2f} s, "
          f"CPU / wall {cur_cpu / cur_wall:.2f})")
    meets_busy = ratio is not None and ratio <= TARGET_RATIO
    if ratio is not None:
        print(f"busy target (wall <= {TARGET_RATIO:g} x the baseline's, paired): "
              f"{'met' if meets_busy else 'not met'} ({ratio:.2f} x)")
    which = "idle" if idle else "busy"
    ok = meets_idle if idle else meets_busy
    print(f"verdict: the machine was {which} at the start -> the {which} target applies: "
          f"{'MET' if ok else 'NOT MET'}")
    return ok


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
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="paired runs per side (default 3)")
    ap.add_argument("--memory", action="store_true", help="also the peak memory at two line counts")
    add_baseline_args(ap)
    a = ap.parse_args()
    sides = [Side.current()] if a.no_baseline else [Side.current(), Side.of_rev(a.baseline)]
    idle = _idle()
    print(f"before: {load_line()} ({'idle' if idle else 'busy'})")
    print(f"whole default `reproduce` processes, {a.repeat} paired run(s) per side:")
    times = ab(sides, a.repeat)
    print(f"after:  {load_line()}")
    report(times, idle)
    if a.memory:
        peaks = {n: peak_rss_mib(n, MEMORY_COLUMNS) for n in MEMORY_LINES}
        for n, (mib, wall) in peaks.items():
            print(f"peak RSS, {n} lines x {MEMORY_COLUMNS} columns: {mib:7.1f} MiB ({wall:.1f} s)")
        lo, hi = (peaks[n][0] for n in MEMORY_LINES)
        print(f"ratio {MEMORY_LINES[1]} / {MEMORY_LINES[0]} lines: {hi / lo:.2f} (target: at most 1.2)")


if __name__ == "__main__":
    main()
