"""Cost of ``simulate`` (stage images + exact truth in one pass) against the render + sensor
steps of ``reproduce``, and its peak memory at two numbers of lines.

1. Time: ``simulate`` at the default size (1024 lines x 1024 columns, M = 100) with stages
   {10, 80}, truth included (``mean_dn``, ``photons``, ``reflectance``, ``clipped``, ``gamma_hdr``),
   against the pass ``reproduce`` made before it ran through ``simulate``: render set-up, every
   frame rendered and streamed through the sensor and DTDI for its 21 stages
   (:func:`bench_sim.sensor.stream.sensor_dtdi_pass`). Prints the ratio (target <= 1).
2. Memory: peak of numpy's allocations (``tracemalloc``; Mitsuba's own buffers are not seen)
   of ``simulate`` with stages {10, 80} at two line counts, split into what grows with the
   lines: the requested stage images (dataset), and the texels the render's run texture holds
   (a few blocks of rows, rasterised as the pass reaches them).

Usage: python benchmarks/bench_simulate.py [--lines-a 512] [--lines-b 2048] [--skip-time]
"""

from __future__ import annotations

import argparse
import gc
import time
import tracemalloc

import numpy as np

from bench_sim.config import load_config, with_overrides
from bench_sim.pipeline import run_pass
from bench_sim.workflows.reproduce.run import FIG3_STAGES

STAGES = (10, 80)


def _reproduce_pass(cfg) -> float:
    from bench_sim.render.exposures import iter_photon_frames, prepare
    from bench_sim.sensor.stream import sensor_dtdi_pass

    stages = sorted(set(FIG3_STAGES) | {cfg.fusion.mu1, cfg.fusion.mu2})
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    setup = prepare(cfg, cfg.lines + max(stages) - 1, rng)
    sensor_dtdi_pass(
        iter_photon_frames(setup, chunk=64), cfg.sensor, cfg.dtdi, setup.geom.t_int_s, stages, rng,
        lines=cfg.lines,
    )
    return time.perf_counter() - t0


def _simulate(cfg) -> tuple[float, dict]:
    t0 = time.perf_counter()
    res = run_pass(cfg, STAGES, 0, truth=True)
    return time.perf_counter() - t0, res.timings_s


def _peak(cfg) -> tuple[float, float, float]:
    """Peak traced MiB of a simulate pass, its dataset's MiB and the run texture's MiB."""
    gc.collect()
    tracemalloc.start()
    res = run_pass(cfg, STAGES, 0, truth=True)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    mib = 1 / 2**20
    return peak * mib, res.dataset.nbytes * mib, res.setup.grid.held_bytes * mib


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines-a", type=int, default=512)
    ap.add_argument("--lines-b", type=int, default=2048)
    ap.add_argument("--skip-time", action="store_true")
    a = ap.parse_args()
    cfg = load_config()
    if not a.skip_time:
        t_rep = _reproduce_pass(cfg)
        t_sim, steps = _simulate(cfg)
        print(f"default size: {cfg.lines} lines x {cfg.sensor.columns} columns, M = {cfg.sensor.rows}")
        print(f"  reproduce render + sensor/DTDI (21 stages, {cfg.lines + 99} frames): {t_rep:7.2f} s")
        print(f"  simulate stages {set(STAGES)} + truth ({cfg.lines + 79} frames):    {t_sim:7.2f} s")
        for k, v in steps.items():
            print(f"    {k:<14} {v:7.2f} s")
        print(f"  ratio simulate / reproduce pass = {t_sim / t_rep:.2f} (target <= 1.0)")
    rows = []
    for lines in (a.lines_a, a.lines_b):
        peak, ds_mib, tex_mib = _peak(with_overrides(cfg, {"lines": lines}))
        rows.append((lines, peak, ds_mib, tex_mib))
        print(f"  {lines:6d} lines: peak {peak:8.1f} MiB (numpy), dataset {ds_mib:7.1f} MiB, "
              f"run texture held {tex_mib:7.1f} MiB")
    (l1, p1, d1, t1), (l2, p2, d2, t2) = rows
    per_line = 2**20 / (l2 - l1)
    kib = per_line / 1024
    print(f"  growth per line: peak {(p2 - p1) * kib:.1f} KiB, of which stage images {(d2 - d1) * kib:.1f} "
          f"KiB and the render's run texture {(t2 - t1) * kib:.1f} KiB (the blocks of rows it keeps)")


if __name__ == "__main__":
    main()
