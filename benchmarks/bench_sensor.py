"""Benchmark: sensor (EMVA 1288 pixel model) + DTDI throughput and streaming memory.

Prints
* throughput in pixel-frames per second of expose + DTDI at 100 x 1024 pixels per frame, for
  the paper's two stages (10, 80) and for the Fig. 3 sweep (stages 5..100 step 5), over a pass
  of 1,124 frames (1,024 lines with 100 rows, the default reproduce job), split into the pixel
  model alone and the DTDI accumulation alone;
* peak traced memory (tracemalloc) of a streaming pass that consumes the lines as they come,
  for 1,000 and 10,000 lines: DTDI alone at 100 x 1024, and sensor + DTDI at 100 x 128.

Run: ``.venv/bin/python benchmarks/bench_sensor.py`` (about a minute on one core).
"""

from __future__ import annotations

import gc
import time
import tracemalloc
from collections.abc import Iterator

import numpy as np

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.sensor.dtdi import DTDIAccumulator, frames_needed
from bench_sim.sensor.emva import draw_fixed_pattern, expose
from bench_sim.sensor.pipeline import DEFAULT_CHUNK_FRAMES, iter_sensor_dtdi

ROWS, COLS, LINES = 100, 1024, 1024
T_INT_S = 100e-6
PAPER_STAGES = [10, 80]
SWEEP_STAGES = list(range(5, 101, 5))


SCENE_PERIOD = 1024


def photon_stream(n_frames: int, rows: int, cols: int, chunk: int, seed: int = 0) -> Iterator[np.ndarray]:
    """A moving scene (one row per frame, row i of frame k sees line k - i) of uniformly
    distributed 0..3000 photons per pixel per frame, repeating every 1,024 lines so that the
    stream itself holds O(1) memory; yielded in chunks of frames."""
    rng = np.random.default_rng(seed)
    scene = rng.uniform(0.0, 3000.0, size=(SCENE_PERIOD, cols))
    idx = np.arange(rows)
    for start in range(0, n_frames, chunk):
        ks = np.arange(start, min(start + chunk, n_frames))
        yield scene[(ks[:, None] - idx[None, :]) % SCENE_PERIOD]


def throughput(stages: list[int]) -> dict[str, float]:
    sensor = SensorConfig(rows=ROWS, columns=COLS)
    n_frames = frames_needed(LINES, [ROWS])
    frames = list(photon_stream(n_frames, ROWS, COLS, DEFAULT_CHUNK_FRAMES))
    px_frames = n_frames * ROWS * COLS

    rng = np.random.default_rng(1)
    fixed = draw_fixed_pattern(sensor, rng)
    t0 = time.perf_counter()
    raw = [expose(f, sensor, fixed, T_INT_S, rng) for f in frames]
    t_sensor = time.perf_counter() - t0

    acc = DTDIAccumulator(COLS, stages, 12, sensor.black_offset_dn)
    t0 = time.perf_counter()
    for r in raw:
        acc.push_many(r)
    t_dtdi = time.perf_counter() - t0

    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    n_lines = 0
    for got in iter_sensor_dtdi(iter(frames), sensor, DTDIConfig(), T_INT_S, stages, rng):
        n_lines += len(got[stages[-1]])
    t_all = time.perf_counter() - t0
    return {
        "frames": n_frames,
        "sensor_s": t_sensor,
        "dtdi_s": t_dtdi,
        "total_s": t_all,
        "sensor_px_frames_per_s": px_frames / t_sensor,
        "dtdi_px_frames_per_s": px_frames / t_dtdi,
        "total_px_frames_per_s": px_frames / t_all,
    }


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
    rng = np.random.default_rng(0)
    for _ in iter_sensor_dtdi(
        photon_stream(n_frames, ROWS, cols, DEFAULT_CHUNK_FRAMES), sensor, DTDIConfig(), T_INT_S,
        SWEEP_STAGES, rng,
    ):
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def main() -> None:
    print(f"sensor + DTDI, {ROWS} x {COLS} pixels per frame, {LINES} lines "
          f"({frames_needed(LINES, [ROWS])} frames), one core")
    for name, stages in (("stages 10, 80", PAPER_STAGES), ("stages 5..100/5", SWEEP_STAGES)):
        r = throughput(stages)
        print(
            f"  {name:<16}: sensor {r['sensor_px_frames_per_s'] / 1e6:6.1f} M px-frames/s "
            f"({r['sensor_s']:.2f} s) | DTDI {r['dtdi_px_frames_per_s'] / 1e6:6.1f} M px-frames/s "
            f"({r['dtdi_s']:.2f} s) | both, streamed {r['total_px_frames_per_s'] / 1e6:6.1f} M "
            f"px-frames/s ({r['total_s']:.2f} s)"
        )
    print("peak traced memory of a streaming pass (lines consumed as they come), stages 5..100/5;")
    print(f"  sensor + DTDI holds a chunk of {DEFAULT_CHUNK_FRAMES} frames (photons, electrons, DN)")
    for n in (1_000, 10_000):
        print(f"  DTDI alone, {ROWS} x {COLS}, {n:>6} lines: {peak_dtdi_only(n) / 2**20:7.2f} MiB")
    for n in (1_000, 10_000):
        print(f"  sensor + DTDI, {ROWS} x 128, {n:>6} lines: {peak_sensor_dtdi(n) / 2**20:7.2f} MiB")


if __name__ == "__main__":
    main()
