"""Fusion benchmark: eq. 11 versus the other merges and the display transforms.

Prints, for a pair of stage images of LINES x COLUMNS (default 1024 x 1024, 12-bit, stages
10 / 80): ms per call of every fusion method and Gamma_TRA transform, and each one's time as a
ratio to the paper's eq. 11 (the on-board candidate: one compare and one multiply per pixel).
Also the wall time of the whole-chain dynamic-range measurement the reproduce job runs.

Usage: python benchmarks/bench_fusion.py [--lines 1024] [--columns 1024] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion import (
    TONEMAP_METHODS,
    fuse_dtdi_hdr_eq11,
    fuse_stages_highest_unsaturated,
    fuse_stages_inverse_variance,
    merge_debevec_opencv,
    merge_mertens_opencv,
    tone_map,
)
from bench_sim.measure.chain_dr import measure_chain_dynamic_range


def _best_ms(func: Callable[[], Any], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        func()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=1024)
    ap.add_argument("--columns", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()

    rng = np.random.default_rng(0)
    s = np.exp(rng.uniform(np.log(0.5), np.log(450.0), (a.lines, a.columns)))  # DN per read
    g1 = np.minimum(np.round(10 * s + 3 * rng.standard_normal(s.shape)), 4095).clip(0)
    g2 = np.minimum(np.round(80 * s + 9 * rng.standard_normal(s.shape)), 4095).clip(0)
    g40 = np.minimum(np.round(40 * s + 6 * rng.standard_normal(s.shape)), 4095).clip(0)
    pair = {10: g1, 80: g2}
    hdr = fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12)

    cases: list[tuple[str, Callable[[], Any]]] = [
        ("eq. 11 (paper)", lambda: fuse_dtdi_hdr_eq11(g1, g2, mu1=10, mu2=80, beta=12)),
        ("highest unsaturated, 2 stages", lambda: fuse_stages_highest_unsaturated(pair, beta=12)),
        (
            "highest unsaturated, 3 stages",
            lambda: fuse_stages_highest_unsaturated({10: g1, 40: g40, 80: g2}, beta=12),
        ),
        (
            "inverse variance, 2 stages",
            lambda: fuse_stages_inverse_variance(
                pair, beta=12, conversion_gain_dn_per_e=0.072, dark_noise_e=13.0
            ),
        ),
        ("Debevec (OpenCV)", lambda: merge_debevec_opencv(pair, beta=12)),
        ("Mertens (OpenCV)", lambda: merge_mertens_opencv(pair, beta=12)),
    ]
    cases += [
        (f"Gamma_TRA {m}", lambda m=m: tone_map(hdr.hdr, m, full_scale_dn=hdr.full_scale_dn))
        for m in TONEMAP_METHODS
    ]
    print(f"stage images {a.lines} x {a.columns}, beta 12, stages 10 / 80; best of {a.repeat}")
    base = _best_ms(cases[0][1], a.repeat)
    print(f"\n{'method':<34} {'ms/call':>9} {'x eq. 11':>9}")
    for name, func in cases:
        ms = base if func is cases[0][1] else _best_ms(func, a.repeat)
        print(f"{name:<34} {ms:9.2f} {ms / base:9.1f}")

    t0 = time.perf_counter()
    r = measure_chain_dynamic_range(BenchConfig(), 0).as_dict()
    dt = time.perf_counter() - t0
    print(
        f"\nmeasure_chain_dynamic_range (whole chain, {len(r['photons'])} levels, "
        f"{r['lines']} x {r['columns']} x 2 images): {dt:.2f} s; "
        f"HDR - Gamma1 = {r['delta_db_vs_gamma1']:.2f} dB; HDR - Gamma2 = {r['delta_db_vs_gamma2']:.2f} dB "
        f"(eq. 15: {r['eq15_db']:.2f} dB)"
    )


if __name__ == "__main__":
    main()
