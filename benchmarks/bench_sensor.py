"""Benchmark: the sensor (EMVA 1288 pixel model) + DTDI pass on one thread, A/B against the
baseline revision, and streaming memory.

Prints
* pixel-frames per CPU second of the one-thread sensor + DTDI pass (``iter_sensor_dtdi``,
  ``BENCH_SIM_THREADS=1``) at 100 x 1024 pixels per frame over 1,123 frames (1,024 lines with
  100 rows, the default reproduce job), stages {10, 80} (and 5..100/5 with ``--sweep``), with the
  ``hybrid`` and the exact ``poisson`` shot-noise samplers: this checkout against the baseline
  revision (:data:`baseline.BASELINE_REV`, exported by ``git archive`` and run with
  ``PYTHONPATH``, see ``benchmarks/baseline.py``). Every run is its own process running
  :data:`PASS_SCRIPT`, which builds the photon frames, warms up on a short pass, then times one
  whole pass in CPU seconds (``time.process_time``: the pass's own work, whatever else the
  machine runs). The sides alternate (A, B, A, B, ...); medians of ``--repeat`` runs, their ratio
  and the load average are printed;
* peak traced memory (tracemalloc) of a streaming pass of this checkout that consumes the lines
  as they come, for 1,000 and 10,000 lines: DTDI alone at 100 x 1024, and sensor + DTDI at
  100 x 128.

The photons are a moving scene of uniformly distributed 0..3000 photons per pixel per frame
(0..1650 mean electrons: 2 % of the reads below the hybrid sampler's 30 e- switch-over).

Run: ``.venv/bin/python benchmarks/bench_sensor.py [--repeat 3] [--sweep] [--baseline REV]``
(about 1 minute per sampler and stage set with 3 repeats).
"""

from __future__ import annotations

import argparse
import gc
import os
import subprocess
import sys
import tracemalloc
from collections.abc import Iterator

import numpy as np
from baseline import Side, add_baseline_args, load_line, median, paired

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.runtime.jit import compiled
from bench_sim.sensor import diagonal_sums, exposure_kernel
from bench_sim.sensor.dtdi import DTDIAccumulator, frames_needed
from bench_sim.sensor.stream import DEFAULT_CHUNK_FRAMES, iter_sensor_dtdi

ROWS, COLS, LINES = 100, 1024, 1024
T_INT_S = 100e-6
PAPER_STAGES = [10, 80]
SWEEP_STAGES = list(range(5, 101, 5))
SCENE_PERIOD = 1024

#: The timed pass, run by each side in its own process (``python -c``): argv = sampler, frames,
#: stages (comma-separated). Uses only the API that both revisions share. Prints the pixel-frames
#: per CPU second and the CPU seconds of the pass.
PASS_SCRIPT = """
import sys, time
import numpy as np
import bench_sim
from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.sensor.stream import iter_sensor_dtdi

sampler, n_frames, stages = sys.argv[1], int(sys.argv[2]), [int(m) for m in sys.argv[3].split(",")]
rows, cols, period = 100, 1024, 1024
scene = np.random.default_rng(0).uniform(0.0, 3000.0, size=(period, cols)).astype(np.float32)
idx = np.arange(rows)
frames = [scene[(np.arange(s, min(s + 16, n_frames))[:, None] - idx[None, :]) % period]
          for s in range(0, n_frames, 16)]
sensor = SensorConfig(rows=rows, columns=cols, shot_noise_sampler=sampler)

def run(chunks):
    n = 0
    for got in iter_sensor_dtdi(iter(chunks), sensor, DTDIConfig(), 100e-6, stages, 1):
        n += len(got[stages[-1]])
    return n

run(frames[:8])  # warm-up: imports, first allocations
t0 = time.process_time()
run(frames)
cpu = time.process_time() - t0
print(n_frames * rows * cols / cpu, cpu, bench_sim.__file__)
"""


def photon_stream(n_frames: int, rows: int, cols: int, chunk: int, seed: int = 0) -> Iterator[np.ndarray]:
    """A moving scene (one row per frame, row i of frame k sees line k - i) of uniformly
    distributed 0..3000 photons per pixel per frame, repeating every 1,024 lines so that the
    stream itself holds O(1) memory; yielded in chunks of frames (float32, as rendered)."""
    rng = np.random.default_rng(seed)
    scene = rng.uniform(0.0, 3000.0, size=(SCENE_PERIOD, cols)).astype(np.float32)
    idx = np.arange(rows)
    for start in range(0, n_frames, chunk):
        ks = np.arange(start, min(start + chunk, n_frames))
        yield scene[(ks[:, None] - idx[None, :]) % SCENE_PERIOD]


def pass_rate(side: Side, sampler: str, stages: list[int]) -> tuple[float, float]:
    """One timed one-thread pass of ``side`` in its own process: (pixel-frames per CPU second,
    CPU seconds of the pass)."""
    n_frames = frames_needed(LINES, [ROWS])
    # -P: no current folder on sys.path, so that PYTHONPATH picks the side's package
    argv = [sys.executable, "-P", "-c", PASS_SCRIPT, sampler, str(n_frames), ",".join(map(str, stages))]
    done = subprocess.run(argv, env=side.env(BENCH_SIM_THREADS="1"), capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{side.name}: the pass exited {done.returncode}: {done.stderr[-2000:]}")
    rate, cpu, package = done.stdout.split()[-3:]
    if side.tree is not None and not package.startswith(str(side.tree)):
        raise RuntimeError(f"{side.name}: the pass imported {package}, not the side's tree {side.tree}")
    return float(rate), float(cpu)


def throughput(sides: list[Side], sampler: str, stages: list[int], repeat: int) -> None:
    """Interleaved runs of every side; medians and the ratio to the last side (the baseline)."""
    runs = paired(sides, lambda side, _i: pass_rate(side, sampler, stages), repeat)
    rates = {name: median([r for r, _ in got]) for name, got in runs.items()}
    base = rates[sides[-1].name]
    for side in sides:
        got = runs[side.name]
        rate = rates[side.name]
        each = ", ".join(f"{r / 1e6:.1f}" for r, _ in got)
        print(f"    {side.name:<22} {rate / 1e6:6.1f} M pixel-frames/CPU s  (runs: {each}; "
              f"{median([c for _, c in got]):.2f} CPU s)  ratio {rate / base:4.2f}x")


def peak_dtdi_only(n_lines: int) -> int:
    frame = np.random.default_rng(0).integers(0, 1024, size=(ROWS, COLS)).astype(np.uint16)
    gc.collect()
    tracemalloc.start()
    acc = DTDIAccumulator(COLS, SWEEP_STAGES, 12, 20.0)  # its buffer is counted
    for k in range(frames_needed(n_lines, SWEEP_STAGES)):
        frame[k % ROWS, k % COLS] ^= 1
        acc.push(frame)  # lines consumed and dropped
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def peak_sensor_dtdi(n_lines: int, cols: int = 128) -> int:
    sensor = SensorConfig(rows=ROWS, columns=cols)
    n_frames = frames_needed(n_lines, SWEEP_STAGES)
    gc.collect()
    tracemalloc.start()  # counts the photon stream, fixed pattern, chunks and DTDI buffer
    for _ in iter_sensor_dtdi(
        photon_stream(n_frames, ROWS, cols, DEFAULT_CHUNK_FRAMES), sensor, DTDIConfig(), T_INT_S,
        SWEEP_STAGES, 0,
    ):
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sweep", action="store_true", help="also stages 5..100/5")
    ap.add_argument("--samplers", default="hybrid,poisson", help="comma-separated")
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory section")
    add_baseline_args(ap)
    a = ap.parse_args()
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    print(f"sensor + DTDI on 1 thread, {ROWS} x {COLS} pixels per frame, {LINES} lines "
          f"({frames_needed(LINES, [ROWS])} frames); median of {a.repeat} runs, interleaved, each "
          f"in its own process; {load_line()} at the start")
    stage_sets = [("stages 10, 80", PAPER_STAGES)] + ([("stages 5..100/5", SWEEP_STAGES)] if a.sweep else [])
    for name, stages in stage_sets:
        for sampler in a.samplers.split(","):
            print(f"  {name}, {sampler} sampler:")
            throughput(sides, sampler, stages, a.repeat)
    print(f"  {load_line()} at the end")
    if a.no_memory:
        return
    os.environ["BENCH_SIM_THREADS"] = "1"
    for loop in diagonal_sums.LOOPS + exposure_kernel.LOOPS:  # numba's one-off set-up: not traced
        compiled(*loop)
    print("peak traced memory of a streaming pass (lines consumed as they come), stages 5..100/5;")
    print(f"  sensor + DTDI holds a few chunks of {DEFAULT_CHUNK_FRAMES} frames (photons, electrons, DN)")
    for n in (1_000, 10_000):
        print(f"  DTDI alone, {ROWS} x {COLS}, {n:>6} lines: {peak_dtdi_only(n) / 2**20:7.2f} MiB")
    for n in (1_000, 10_000):
        print(f"  sensor + DTDI, {ROWS} x 128, {n:>6} lines: {peak_sensor_dtdi(n) / 2**20:7.2f} MiB")


if __name__ == "__main__":
    main()
