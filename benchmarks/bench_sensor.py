"""Benchmark: sensor (EMVA 1288 pixel model) + DTDI throughput against the kept baseline, and
streaming memory.

Prints
* throughput of expose + DTDI at 100 x 1024 pixels per frame over a pass of 1,123 frames (1,024
  lines with 100 rows, the default reproduce job), stages 5..100 step 5 (Fig. 3) and 10, 80:
  the **baseline** is the pass as it was before the per-chunk streams (kept below, verbatim: one
  generator, exact Poisson draws, float64, one thread, DTDI frame by frame); it is timed in the
  same process, interleaved with the current pass (``iter_sensor_dtdi``) on 1 thread and on
  ``BENCH_SIM_THREADS`` threads (default: the usable cores), with the ``hybrid`` and the exact
  ``poisson`` shot-noise samplers. Best of ``--repeat`` runs each, ratios to the baseline;
* peak traced memory (tracemalloc) of a streaming pass that consumes the lines as they come,
  for 1,000 and 10,000 lines: DTDI alone at 100 x 1024, and sensor + DTDI at 100 x 128.

The photons are a moving scene of uniformly distributed 0..3000 photons per pixel per frame
(0..1650 mean electrons: 2 % of the reads below the hybrid sampler's 30 e- switch-over).

Run: ``.venv/bin/python benchmarks/bench_sensor.py [--repeat 3]`` (one to two minutes).
"""

from __future__ import annotations

import argparse
import gc
import os
import time
import tracemalloc
from collections.abc import Iterator

import numpy as np

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.runtime.parallel import thread_count
from bench_sim.sensor.dtdi import DTDIAccumulator, frames_needed
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern, pixel_saturation_dn
from bench_sim.sensor.stream import DEFAULT_CHUNK_FRAMES, iter_sensor_dtdi

ROWS, COLS, LINES = 100, 1024, 1024
T_INT_S = 100e-6
PAPER_STAGES = [10, 80]
SWEEP_STAGES = list(range(5, 101, 5))
SCENE_PERIOD = 1024


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


# --- the baseline: the sensor pass before this change, kept verbatim -----------------------------


def baseline_expose(
    photons: np.ndarray, sensor: SensorConfig, fixed: FixedPattern, t_int_s: float, rng: np.random.Generator
) -> np.ndarray:
    """``bench_sim.sensor.emva.expose`` before the hybrid sampler (no ``saturated`` output)."""
    p = np.asarray(photons, dtype=np.float64)
    light_e = p * (sensor.quantum_efficiency * fixed.prnu_gain)
    dark_e = fixed.dark_current_e_s * float(t_int_s)
    electrons = rng.poisson(light_e + dark_e).astype(np.float64)
    np.minimum(electrons, sensor.full_well_e, out=electrons)
    electrons += sensor.read_noise_e * rng.standard_normal(p.shape, dtype=np.float32)
    dn = electrons
    dn *= sensor.conversion_gain_dn_per_e
    dn += sensor.black_offset_dn + fixed.column_offset_dn
    top = float(pixel_saturation_dn(sensor))
    np.rint(dn, out=dn)
    np.clip(dn, 0.0, top, out=dn)
    return dn.astype(np.uint16)


def baseline_pass(frames: list[np.ndarray], sensor: SensorConfig, stages: list[int]) -> int:
    """One generator, chunks exposed in order, DTDI frame by frame (``DTDIAccumulator.push``)."""
    rng = np.random.default_rng(1)
    fixed = draw_fixed_pattern(sensor, rng)
    acc = DTDIAccumulator(COLS, stages, 12, sensor.black_offset_dn, pedestal_dn=64)
    n_lines = 0
    for chunk in frames:
        for f in baseline_expose(chunk, sensor, fixed, T_INT_S, rng):
            n_lines += len(acc.push(f))
    return n_lines


def current_pass(frames: list[np.ndarray], sensor: SensorConfig, stages: list[int]) -> int:
    n_lines = 0
    for got in iter_sensor_dtdi(iter(frames), sensor, DTDIConfig(), T_INT_S, stages, 1):
        n_lines += len(got[stages[-1]])
    return n_lines


def timed(fn, *args) -> float:
    t0 = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t0


def throughput(stages: list[int], repeat: int, threads: int) -> None:
    n_frames = frames_needed(LINES, [ROWS])
    frames = list(photon_stream(n_frames, ROWS, COLS, DEFAULT_CHUNK_FRAMES))
    px = n_frames * ROWS * COLS
    runs: dict[str, list[float]] = {}
    variants = [("baseline (1 thread, exact Poisson)", None, "poisson")]
    for n in sorted({1, threads}):
        for sampler in ("hybrid", "poisson"):
            variants.append((f"current, {n} thread{'s' if n > 1 else ''}, {sampler}", n, sampler))
    for _ in range(repeat):  # interleaved, so that a slow spell of the machine hits all alike
        for name, n, sampler in variants:
            sensor = SensorConfig(rows=ROWS, columns=COLS, shot_noise_sampler=sampler)
            if n is None:
                runs.setdefault(name, []).append(timed(baseline_pass, frames, sensor, stages))
            else:
                os.environ["BENCH_SIM_THREADS"] = str(n)
                runs.setdefault(name, []).append(timed(current_pass, frames, sensor, stages))
    base = min(runs[variants[0][0]])
    for name, *_ in variants:
        best = min(runs[name])
        print(f"    {name:<36} {best:6.2f} s  {px / best / 1e6:6.1f} M pixel-frames/s  "
              f"ratio {base / best:5.2f}x")


def peak_dtdi_only(n_lines: int) -> int:
    frame = np.random.default_rng(0).integers(0, 1024, size=(ROWS, COLS)).astype(np.uint16)
    gc.collect()
    tracemalloc.start()
    acc = DTDIAccumulator(COLS, SWEEP_STAGES, 12, 20.0)  # its ring is counted
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
    tracemalloc.start()  # counts the photon stream, fixed pattern, chunks and ring
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
    a = ap.parse_args()
    threads = thread_count()
    print(f"sensor + DTDI, {ROWS} x {COLS} pixels per frame, {LINES} lines "
          f"({frames_needed(LINES, [ROWS])} frames); threads: {threads} (BENCH_SIM_THREADS or the "
          f"usable cores); best of {a.repeat}, interleaved")
    for name, stages in (("stages 5..100/5", SWEEP_STAGES), ("stages 10, 80", PAPER_STAGES)):
        print(f"  {name}:")
        throughput(stages, a.repeat, threads)
    os.environ["BENCH_SIM_THREADS"] = str(threads)
    print("peak traced memory of a streaming pass (lines consumed as they come), stages 5..100/5;")
    print(f"  sensor + DTDI holds a few chunks of {DEFAULT_CHUNK_FRAMES} frames (photons, electrons, DN)")
    for n in (1_000, 10_000):
        print(f"  DTDI alone, {ROWS} x {COLS}, {n:>6} lines: {peak_dtdi_only(n) / 2**20:7.2f} MiB")
    for n in (1_000, 10_000):
        print(f"  sensor + DTDI, {ROWS} x 128, {n:>6} lines: {peak_sensor_dtdi(n) / 2**20:7.2f} MiB")


if __name__ == "__main__":
    main()
