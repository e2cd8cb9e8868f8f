"""Wall time of the default full ``bench-sim reproduce`` (1024 lines x 1024 columns, M = 100),
per step, against the 30 s target; and the ``--quick`` preset for comparison.

Usage: python benchmarks/bench_reproduce.py [--skip-full]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from pathlib import Path

from bench_sim.config import load_config
from bench_sim.experiments.reproduce import run_reproduce

TARGET_S = 30.0


def _run(quick: bool) -> dict:
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        return run_reproduce(load_config(), seed=0, out=Path(tmp), quick=quick)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--skip-full", action="store_true")
    a = ap.parse_args()
    runs = [("quick", True)] + ([] if a.skip_full else [("full", False)])
    for name, quick in runs:
        m = _run(quick)
        pixel_frames = m["frames"] * m["rows"] * m["columns"]  # every sensor pixel of every frame
        print(f"{name}: {m['lines']} lines x {m['columns']} columns, M = {m['rows']}, "
              f"{m['frames']} frames, {len(m['stages'])} stages")
        for step, s in m["timings_s"].items():
            print(f"  {step:<14} {s:7.2f} s  ({100 * s / m['wall_s']:4.1f} %)")
        print(f"  {'total':<14} {m['wall_s']:7.2f} s  = {m['wall_s'] / TARGET_S:.2f} x the {TARGET_S:.0f} s "
              f"target; {pixel_frames / m['wall_s'] / 1e6:.1f} M sensor pixel-frames/s end to end")


if __name__ == "__main__":
    main()
