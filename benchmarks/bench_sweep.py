"""Points per minute of a light-power sweep at ``--quick`` size on 2 Dask workers, this checkout
against the main branch before the speed work (A/B, :mod:`baseline`), and the time to the first
finished point.

Both sides run the same spec (``--points`` light powers of the paper rig's spot, ``--quick``:
512 x 256, M = 100) as a separate ``bench-sim sweep --workers 2`` process, as a user would, in
pairs interleaved A, B, A, B (``--repeat`` pairs), so a change of the machine's load hits both
alike. Per side: the median wall time and CPU time (user + system of the process and its
workers), points per minute (points / median wall), the time from the process's start to the
first point's journal record (``points/NNNNNN.json``, its modification time), and the Mitsuba
renders (``sweep.json``). The ratio is this checkout's points per minute over the baseline's.

What the sweep's points share -- the light records (a power changes none), the camera's
measured dynamic range, the rasterised target -- is made once per sweep on this checkout; the
baseline makes the records and the DR once per worker and rasterises the target per point.

The powers stop at ``--max-power`` (default 256 W/m^2): above, the spot clips and the exact
truth of the clipped pixels dominates a point on both sides (a cost of the sensor's truth, not
of what this benchmark is about).

Usage: python benchmarks/bench_sweep.py [--points 8] [--repeat 2] [--workers 2]
       [--baseline REV | --no-baseline] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline import Side, add_baseline_args, load_line, paired, print_rates, workflow_run  # noqa: E402

from bench_sim.config import SCENES_DIR  # noqa: E402

SPEC = """
name = "bench_light_power"
base = "{base}"
quick = true
seed = 0
[[parameters]]
key = "lights.strong.irradiance_w_m2"
logspace = {{ start = 8.0, stop = {stop}, num = {points} }}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=2, help="A/B pairs")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-power", type=float, default=256.0, help="highest spot irradiance [W/m^2]")
    ap.add_argument("--keep", type=Path, default=None, help="keep the sweeps in this folder")
    add_baseline_args(ap)
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_")) if a.keep is None else a.keep
    tmp.mkdir(parents=True, exist_ok=True)
    spec = tmp / "light_power.toml"
    spec.write_text(SPEC.format(base=SCENES_DIR / "paper_rig.toml", stop=a.max_power, points=a.points))
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    first: dict[str, list[float]] = {s.name: [] for s in sides}
    renders: dict[str, int] = {}

    def run(side: Side, i: int) -> tuple[float, float]:
        def check(out: Path) -> None:
            meta = json.loads((out / "sweep.json").read_text())
            if meta["ok"] != a.points:
                raise RuntimeError(f"{side.name}: {meta['ok']} of {a.points} points ok")
            renders[side.name] = int(meta["mitsuba_renders"])

        return workflow_run(sides, side, i, tmp, "sweep", spec, a.workers, "points", "point", first, check)

    print(f"{a.points}-point light-power sweep (8 .. {a.max_power:g} W/m^2) at --quick size, "
          f"{a.workers} workers, each run a bench-sim process; {load_line()}", flush=True)
    try:
        times = paired(sides, run, a.repeat)
    finally:
        if a.keep is None:
            shutil.rmtree(tmp, ignore_errors=True)
    print_rates(sides, times, first, a.points, "points", ("renders", renders))


if __name__ == "__main__":
    main()
