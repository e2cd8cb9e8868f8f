"""Render benchmark: 100 rows x 1024 columns frames with both engines.

Prints, for the default rig: ms per frame of each engine (the fast engine's one-off set-up shown
apart and amortised over a full 1,124-frame pass), the speed ratio, and each engine's mean
absolute error against a high-spp reference of the same frames (relative to the mean signal).
Also the reference engine's cost with the trimesh drum versus the analytic cylinder.

Usage: python benchmarks/bench_render.py [--ref-spp 1024] [--frames 4]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bench_sim.config import load_config, with_overrides
from bench_sim.render.exposures import iter_photon_frames, prepare


def _cfg(**over):
    return with_overrides(load_config(), {"sensor": {"rows": 100, "columns": 1024}, **over})


def _frames(cfg, engine, k0, n, seed):
    t0 = time.perf_counter()
    setup = prepare(cfg, n, np.random.default_rng(seed), engine=engine, first_frame=k0)
    t1 = time.perf_counter()
    ph = np.concatenate(list(iter_photon_frames(setup)))
    t2 = time.perf_counter()
    return ph, t1 - t0, t2 - t1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--frames", type=int, default=4, help="frames compared against the reference")
    ap.add_argument("--first", type=int, default=560, help="first frame (560: bar groups in view)")
    ap.add_argument("--pass-frames", type=int, default=1123, help="frames of a full default pass")
    a = ap.parse_args()
    cfg = _cfg()
    print(f"frame: {cfg.sensor.rows} x {cfg.sensor.columns}, frames {a.first}..{a.first + a.frames - 1}")
    print(f"high-spp reference: {a.ref_spp} spp ...", flush=True)
    ref, _, t_ref_hi = _frames(_cfg(render={"spp": a.ref_spp}), "reference", a.first, a.frames, 99)
    mean = ref.mean()

    def err(x):
        return float(np.abs(x - ref).mean() / mean)

    rows = []
    ref_ms = {}
    for spp in (16, 64, 256):
        ph, t_set, t_run = _frames(_cfg(render={"spp": spp}), "reference", a.first, a.frames, 1)
        ref_ms[spp] = t_run / a.frames * 1e3
        rows.append((f"reference {spp:>3} spp", ref_ms[spp], (t_set + t_run) / a.frames * 1e3, err(ph)))
    ph, _, _ = _frames(cfg, "fast", a.first, a.frames, 2)
    fast_err = err(ph)
    # the fast engine's cost on a full pass: one set-up, then every frame
    _, t_set_full, t_run_full = _frames(cfg, "fast", 0, a.pass_frames, 2)
    per_frame = t_run_full / a.pass_frames * 1e3
    amortised = (t_set_full + t_run_full) / a.pass_frames * 1e3
    ss = cfg.render.subpixels
    rows.append((f"fast (16 spp x {ss}x{ss} records)", per_frame, amortised, fast_err))
    print(f"\n{'engine':<34} {'ms/frame':>9} {'incl. set-up':>13} {'MAE vs ref':>11}")
    for name, ms, ms_all, e in rows:
        print(f"{name:<34} {ms:9.2f} {ms_all:13.2f} {100 * e:10.2f}%")
    print(f"(fast set-up: {t_set_full:.2f} s, amortised over a {a.pass_frames}-frame pass; "
          f"reference set-up amortised over {a.frames} frames)")
    for spp in (16, 256):
        e_ref = rows[[16, 64, 256].index(spp)][3]
        print(f"speed ratio reference({spp} spp) / fast: {ref_ms[spp] / per_frame:6.1f}x per frame, "
              f"{ref_ms[spp] / amortised:6.1f}x with the fast set-up; error fast / reference: "
              f"{fast_err / e_ref:.2f}")
    # geometry: analytic cylinder vs trimesh drum, reference engine at 16 spp
    _, s_a, r_a = _frames(_cfg(render={"spp": 16}), "reference", a.first, a.frames, 3)
    mesh = _cfg(render={"spp": 16}, drum={"geometry": "mesh"})
    _, s_m, r_m = _frames(mesh, "reference", a.first, a.frames, 3)
    print(f"\nreference 16 spp, analytic cylinder: {r_a / a.frames * 1e3:.1f} ms/frame; "
          f"trimesh drum: {r_m / a.frames * 1e3:.1f} ms/frame (ratio {r_m / r_a:.2f})")


if __name__ == "__main__":
    main()
