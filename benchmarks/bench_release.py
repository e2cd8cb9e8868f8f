"""Issue 38's A/B in one run: this checkout against 0.3.0 (:data:`BASELINE_0_3_0`), whole processes.

Prints, each part paired and interleaved (A, B, A, B, ...; :func:`baseline.paired`) so that a
change of the machine's load hits both sides alike, with the load average:

1. ``reproduce``: the whole default ``bench-sim reproduce`` (``--repeat`` pairs): median wall,
   CPU (user + system) and peak resident memory of the process (``ru_maxrss`` of the one child,
   :func:`peak_process`) per side and their ratios (targets: wall <= 0.75x, peak <= 0.65x); the
   bytes of the output folder per side and which of its data files differ in bytes (the
   ``metrics.json`` and ``report.md`` hold times and are left out; a file only on one side is
   listed as such);
2. ``sweep``: a 6-point light-power sweep at ``--quick`` size on 2 workers (:mod:`bench_sweep`'s
   spec): points per minute and the ratio (target: >= 2x);
3. ``dataset``: 8 samples of the baseline's example spec (``scenes/datasets/example.toml``; the
   current one draws scene keys 0.3.0 lacks), each side with its own rig, on 2 workers: samples
   per minute and the ratio (target: >= 2x);
4. the sensor + DTDI pass on one thread (:mod:`bench_sensor`'s): pixel-frames per CPU second and
   the ratio (target: >= 1, 5 % of noise);
5. ``memory`` (this checkout): peak resident memory of ``reproduce`` and of ``simulate`` (its
   default stages, Zarr) at :data:`MEMORY_LINES` lines of :data:`MEMORY_COLUMNS` columns, and what
   each line adds (``docs/performance.md`` quotes them).

Usage: python benchmarks/bench_release.py [--repeat 3] [--flow-repeat 2] [--baseline REV]
       [--only reproduce,sweep,dataset,sensor]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline import Side, load_line, median, paired, print_rates, workflow_run  # noqa: E402
from bench_sensor import PAPER_STAGES, pass_rate  # noqa: E402
from bench_sweep import SPEC as SWEEP_SPEC  # noqa: E402

from bench_sim.config import SCENES_DIR  # noqa: E402
from bench_sim.workflows.dataset.reader import read_records  # noqa: E402

#: 0.3.0 (the release the issue's numbers were measured on)
BASELINE_0_3_0 = "638a481"
PARTS = ("reproduce", "sweep", "dataset", "sensor", "memory")
MEMORY_LINES = (1024, 4096)
MEMORY_COLUMNS = 256
#: files of ``reproduce`` that hold the run's times (not compared as bytes)
TIMED_FILES = {"metrics.json", "report.md"}


def peak_process(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float, float]:
    """(wall [s], CPU [s], peak resident memory [MiB]) of one process: its own rusage
    (``os.wait4``), so the peak is this child's, not the largest of all children so far."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {proc.returncode}: {err.decode()[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def _data_differences(a: Path, b: Path) -> list[str]:
    """Files of two output folders that differ in bytes or exist on one side only."""
    names = {p.name for p in a.iterdir()} | {p.name for p in b.iterdir()}
    out = []
    for name in sorted(names - TIMED_FILES):
        if not (a / name).exists() or not (b / name).exists():
            out.append(f"{name} (one side only)")
        elif not filecmp.cmp(a / name, b / name, shallow=False):
            out.append(name)
    return out


def reproduce(sides: list[Side], repeat: int, tmp: Path) -> None:
    runs: dict[str, list[tuple[float, float, float]]] = {s.name: [] for s in sides}

    def run(side: Side, i: int) -> tuple[float, float]:
        out = tmp / f"reproduce_{'ab'[sides.index(side)]}_{i}"
        argv = [sys.executable, "-P", "-m", "bench_sim", "reproduce", "--out", str(out)]
        got = peak_process(argv, side.env(), cwd=tmp)
        runs[side.name].append(got)
        print(f"  {side.name:<22} run {i}: {got[0]:6.2f} s wall, {got[1]:6.2f} s CPU, "
              f"peak {got[2]:6.0f} MiB ({load_line()})", flush=True)
        return got[0], got[1]

    print(f"reproduce (default), {repeat} pairs; {load_line()}", flush=True)
    paired(sides, run, repeat)
    med = {n: tuple(median([r[k] for r in rs]) for k in range(3)) for n, rs in runs.items()}
    for name, (wall, cpu, peak) in med.items():
        print(f"  {name:<22} median wall {wall:6.2f} s, CPU {cpu:6.2f} s, peak {peak:6.0f} MiB")
    if len(sides) == 2:
        a, b = (med[s.name] for s in sides)
        print(f"  this checkout / baseline: wall {a[0] / b[0]:.2f}x (target <= 0.75), "
              f"CPU {a[1] / b[1]:.2f}x, peak memory {a[2] / b[2]:.2f}x (target <= 0.65)")
        fa, fb = tmp / "reproduce_a_0", tmp / "reproduce_b_0"
        size = {s: sum(p.stat().st_size for p in f.iterdir()) for s, f in (("a", fa), ("b", fb))}
        print(f"  output folder: {size['a'] / 2**20:.2f} MiB against {size['b'] / 2**20:.2f} MiB")
        diff = _data_differences(fa, fb)
        print("  data files that differ in bytes: " + (", ".join(diff) if diff else "none"))


def scenes(side: Side) -> Path:
    """The side's own scenes folder (each side reads the configs of its own schema)."""
    return SCENES_DIR if side.tree is None else side.tree / "bench_sim" / "scenes"


def sweep(sides: list[Side], repeat: int, tmp: Path, points: int = 6) -> None:
    specs = {}
    for k, side in enumerate(sides):
        specs[side.name] = tmp / f"sweep_{k}.toml"
        specs[side.name].write_text(SWEEP_SPEC.format(base=scenes(side) / "paper_rig.toml", stop=256.0,
                                                      points=points))
    first: dict[str, list[float]] = {s.name: [] for s in sides}

    def run(side: Side, i: int) -> tuple[float, float]:
        def check(out: Path) -> None:
            ok = json.loads((out / "sweep.json").read_text())["ok"]
            if ok != points:
                raise RuntimeError(f"{side.name}: {ok} of {points} points ok")

        return workflow_run(sides, side, i, tmp / "sweep", "sweep", specs[side.name], 2, "points", "point",
                            first, check)

    (tmp / "sweep").mkdir()
    print(f"sweep: {points} light powers at --quick size, 2 workers, {repeat} pairs; {load_line()}",
          flush=True)
    print_rates(sides, paired(sides, run, repeat), first, points, "points")


def dataset(sides: list[Side], repeat: int, tmp: Path, samples: int = 8) -> None:
    (tmp / "dataset").mkdir()
    # one spec for both sides, the baseline's example (the current one draws scene keys it lacks),
    # each side with its own rig and targets
    example = (scenes(sides[-1]) / "datasets" / "example.toml").read_text()
    specs = {}
    for k, side in enumerate(sides):
        text = example.replace('base = "../paper_rig.toml"', f'base = "{scenes(side) / "paper_rig.toml"}"')
        text = text.replace('pattern = "../targets/*.png"', f'pattern = "{scenes(side) / "targets"}/*.png"')
        specs[side.name] = tmp / "dataset" / f"spec_{k}.toml"
        specs[side.name].write_text(text.replace("samples = 16", f"samples = {samples}"))
    first: dict[str, list[float]] = {s.name: [] for s in sides}

    def run(side: Side, i: int) -> tuple[float, float]:
        def check(out: Path) -> None:
            done = sum(1 for r in read_records(out).values() if r.get("status") == "complete")
            if done != samples:
                raise RuntimeError(f"{side.name}: {done} of {samples} samples complete")

        spec = specs[side.name]
        return workflow_run(sides, side, i, tmp / "dataset", "dataset", spec, 2, "samples", "sample", first,
                            check)

    print(f"dataset: {samples} samples of the example spec, 2 workers, {repeat} pairs; {load_line()}",
          flush=True)
    print_rates(sides, paired(sides, run, repeat), first, samples, "samples")


def sensor(sides: list[Side], repeat: int) -> None:
    runs = paired(sides, lambda side, _i: pass_rate(side, "hybrid", PAPER_STAGES), repeat)
    rates = {n: median([r for r, _ in got]) for n, got in runs.items()}
    print(f"sensor + DTDI pass, one thread, stages {PAPER_STAGES}, {repeat} pairs; {load_line()}")
    for side in sides:
        print(f"  {side.name:<22} {rates[side.name] / 1e6:6.1f} M pixel-frames per CPU second")
    if len(sides) == 2:
        print(f"  this checkout / baseline: {rates[sides[0].name] / rates[sides[1].name]:.3f} (target >= 1)")


def memory(tmp: Path) -> None:
    print(f"memory: peak resident memory at {MEMORY_COLUMNS} columns (this checkout); {load_line()}")
    side = Side.current()
    for command in ("reproduce", "simulate"):
        peaks = []
        for lines in MEMORY_LINES:
            cfg = tmp / f"memory_{lines}.toml"
            cfg.write_text(f'base = "{SCENES_DIR / "paper_rig.toml"}"\nlines = {lines}\n[sensor]\n'
                           f"columns = {MEMORY_COLUMNS}\n[target]\npanel_columns = {MEMORY_COLUMNS}\n")
            out = tmp / f"memory_{command}_{lines}"
            argv = [sys.executable, "-P", "-m", "bench_sim", command, str(cfg), "--out", str(out)]
            wall, _, peak = peak_process(argv, side.env(), cwd=tmp)
            peaks.append(peak)
            print(f"  {command:<10} {lines:5d} lines: peak {peak:6.0f} MiB ({wall:.1f} s)", flush=True)
        per_line = (peaks[1] - peaks[0]) * 1024 / (MEMORY_LINES[1] - MEMORY_LINES[0])
        print(f"  {command:<10} {per_line:.0f} KiB per line")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="pairs of reproduce and of the sensor pass")
    ap.add_argument("--flow-repeat", type=int, default=2, help="pairs of the sweep and the dataset")
    ap.add_argument("--baseline", default=BASELINE_0_3_0, help="git revision to compare with")
    ap.add_argument("--only", default=",".join(PARTS), help="comma-separated parts to run")
    a = ap.parse_args()
    parts = [p for p in a.only.split(",") if p]
    if unknown := set(parts) - set(PARTS):
        ap.error(f"--only: unknown {sorted(unknown)}; allowed {list(PARTS)}")
    sides = [Side.current(), Side.of_rev(a.baseline)]
    print(f"this checkout against {a.baseline}; at the start: {load_line()}", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="bench_release_"))
    try:
        for part in parts:
            if part == "reproduce":
                reproduce(sides, a.repeat, tmp)
            elif part == "sweep":
                sweep(sides, a.flow_repeat, tmp)
            elif part == "dataset":
                dataset(sides, a.flow_repeat, tmp)
            elif part == "memory":
                memory(tmp)
            else:
                sensor(sides, a.repeat)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"at the end: {load_line()}")


if __name__ == "__main__":
    main()
