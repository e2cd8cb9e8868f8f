"""Points per minute of a 16-point light-power sweep at ``--quick`` size on 1 and 2 Dask
workers, against running ``bench-sim reproduce --quick`` once per point (what a scenario study
cost before sweeps), and the Mitsuba renders each makes (the fast engine's per-light records
are rendered once per worker and reused for every power).

Every run is a separate ``bench-sim`` process, as a user would start it; all are timed in this
one script run, so the ratios compare like with like on a loaded machine.

Usage: python benchmarks/bench_sweep.py [--points 16] [--reproduce-runs 16]
(``--reproduce-runs k < points`` times k runs and scales to ``points``.)
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_sim.config import SCENES_DIR

SPEC = """
name = "bench_light_power"
base = "{base}"
quick = true
seed = 0
[[parameters]]
key = "lights.strong.irradiance_w_m2"
logspace = {{ start = 8.0, stop = 2048.0, num = {points} }}
"""


def _bench_sim(*args: str) -> tuple[float, float]:
    """Wall time [s] and CPU time [s] (user + system of the process and its workers) of one
    ``bench-sim`` run."""
    exe = Path(sys.executable).with_name("bench-sim")
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([str(exe), *args], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=16)
    ap.add_argument("--reproduce-runs", type=int, default=16)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "light_power.toml"
        spec.write_text(SPEC.format(base=SCENES_DIR / "paper_rig.toml", points=a.points))
        rows = []
        for workers in (1, 2):
            out = Path(tmp) / f"sweep_{workers}"
            wall, cpu = _bench_sim("sweep", str(spec), "--out", str(out), "--workers", str(workers))
            meta = json.loads((out / "sweep.json").read_text())
            assert meta["ok"] == a.points, meta
            name = f"sweep, {workers} worker{'s' if workers > 1 else ''}"
            rows.append((name, wall, cpu, meta["mitsuba_renders"]))
        k = max(1, min(a.reproduce_runs, a.points))
        runs = [_bench_sim("reproduce", "--quick", "--out", str(Path(tmp) / f"rep_{i}")) for i in range(k)]
        # each reproduce process renders its records anew (metrics.json: renders of that process)
        renders = int(json.loads((Path(tmp) / "rep_0" / "metrics.json").read_text())["mitsuba_renders"])
        rows.append((f"reproduce --quick x {a.points}" + ("" if k == a.points else f" (timed {k}, scaled)"),
                     sum(r[0] for r in runs) * a.points / k, sum(r[1] for r in runs) * a.points / k,
                     renders * a.points))
    base, base_cpu = rows[-1][1], rows[-1][2]
    print(f"{a.points}-point light-power sweep at --quick size (512 x 256, M = 100), "
          "each run a bench-sim process")
    print(f"  {'run':<34} {'wall s':>7} {'points/min':>10} {'x reproduce':>11} {'CPU s':>7} "
          f"{'x reproduce':>11} {'Mitsuba renders':>15}")
    for name, wall, cpu, renders in rows:
        print(f"  {name:<34} {wall:7.1f} {60 * a.points / wall:10.2f} {base / wall:11.2f} {cpu:7.1f} "
              f"{base_cpu / cpu:11.2f} {renders:15d}")
    print("  (CPU s: user + system time of the run and its worker processes; on a loaded machine the "
          "wall-time ratios understate what idle cores give)")


if __name__ == "__main__":
    main()
