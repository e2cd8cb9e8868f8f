"""Benchmark: the exact truth of clipped reads (``read_cumulants``) on the reads of real passes,
this checkout against the baseline revision (A/B), and whether both give the same bits.

Two workloads, each captured from one pass with a strong light: every call of
:func:`bench_sim.sensor.expectation.read_cumulants` that the pass's truth makes (21 calls of 16
frames x 80 rows x 256 columns) is recorded with its arguments.

* ``rig``: the paper rig with its strong spot at ``--light`` (default 448 W/m^2), 256 lines of
  256 columns, stages 10 and 80;
* ``dataset``: sample 0 of the example dataset (``scenes/datasets/example.toml``: strong spot
  448 W/m^2, slanted edges, the window on the spot's edge) with its light as drawn, not scaled
  (``scene.peak_of_mu2_clip`` dropped): a third of its reads reach the full well, the case where
  the truth took most of a sample.

Each side then runs :data:`TIME_SCRIPT` in its own process (the side's package first on
``PYTHONPATH``, see ``benchmarks/baseline.py``): one warm-up over all the calls (imports,
compiled loops), then all the calls timed in CPU seconds (``time.process_time``, one thread),
and a SHA-256 digest of every output array. The sides alternate (A, B, A, B, ...).

Prints per workload the sizes (calls, reads, reads near a clip that the quadrature integrates),
per side the median CPU seconds of ``--repeat`` runs and the digest, the ratio baseline / this
checkout, and whether the digests agree (the truth must not change by a bit).

The default baseline is :data:`TRUTH_BASELINE_REV`, main before the quadrature's speed work.

Run: ``.venv/bin/python benchmarks/bench_truth_reads.py [--repeat 5] [--light 448]
[--workloads rig,dataset] [--baseline REV | --no-baseline]`` (about 2 minutes with 5 repeats;
each workload renders first).
"""

from __future__ import annotations

import argparse
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from baseline import Side, add_baseline_args, load_line, median

from bench_sim.config import SCENES_DIR, load_config, with_overrides
from bench_sim.pipeline import run_pass
from bench_sim.sensor import expectation, pass_truth

#: main before the quadrature's speed work (issue 38): the same results, bit for bit
TRUTH_BASELINE_REV = "bc8ae64"
STAGES = [10, 80]
EXAMPLE_SPEC = SCENES_DIR / "datasets" / "example.toml"

#: The timed calls, run by each side in its own process (``python -c``): argv = the pickled calls.
#: Uses only the API that both revisions share. Prints the CPU seconds of all calls, the digest
#: of their outputs and the package's path.
TIME_SCRIPT = """
import hashlib, pickle, sys, time
import bench_sim
from bench_sim.sensor.expectation import ReadModel, read_cumulants

calls = pickle.load(open(sys.argv[1], "rb"))

def run():
    return [read_cumulants(c["lam"], c["det"], c["off"], ReadModel(**c["rm"]), **c["kw"]) for c in calls]

digest = hashlib.sha256()
for out in run():  # warm-up: imports, compiled loops
    for a in out:
        digest.update(a.tobytes())
t0 = time.process_time()
run()
print(time.process_time() - t0, digest.hexdigest()[:16], bench_sim.__file__)
"""


@contextmanager
def recorded_calls() -> Iterator[list[dict[str, Any]]]:
    """Record the arguments of every ``read_cumulants`` call of a pass's truth (copies)."""
    calls: list[dict[str, Any]] = []
    read_cumulants = pass_truth.read_cumulants

    def record(lam: np.ndarray, det: Any, off: Any, rm: expectation.ReadModel, **kw: Any) -> Any:
        keep = {k: v for k, v in kw.items() if k != "out"}
        calls.append({"lam": np.array(lam), "det": np.array(det), "off": np.array(off), "rm": vars(rm),
                      "kw": {k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in keep.items()}})
        return read_cumulants(lam, det, off, rm, **kw)

    pass_truth.read_cumulants = record  # type: ignore[assignment]
    try:
        yield calls
    finally:
        pass_truth.read_cumulants = read_cumulants


def rig_calls(light_w_m2: float, _tmp: Path) -> list[dict[str, Any]]:
    """The calls of the paper rig's pass (workload ``rig``)."""
    cfg = with_overrides(load_config(), {
        "lines": 256, "sensor": {"columns": 256}, "lights": {"strong": {"irradiance_w_m2": light_w_m2}},
    })
    with recorded_calls() as calls:
        run_pass(cfg, STAGES, 0, truth=True)
    return calls


def dataset_calls(_light_w_m2: float, tmp: Path) -> list[dict[str, Any]]:
    """The calls of the example dataset's sample 0, its light not scaled (workload ``dataset``):
    the spec copied with its paths made absolute and without ``peak_of_mu2_clip``."""
    from bench_sim.workflows.dataset.run import run_dataset

    folder = EXAMPLE_SPEC.parent
    text = EXAMPLE_SPEC.read_text()
    text = text.replace('"../', f'"{folder.parent}/')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("peak_of_mu2_clip"))
    spec = tmp / "example_unscaled.toml"
    spec.write_text(text)
    with recorded_calls() as calls:
        run_dataset(spec, tmp / "dataset", workers=0, only=[0])
    return calls


def integrated(calls: list[dict[str, Any]]) -> int:
    """Reads of ``calls`` near a clip (not linear: integrated), counted on this checkout."""
    integrate, near, depth = expectation._integrate_reads, [0], [0]

    def count(lam: np.ndarray, *args: Any, **kw: Any) -> Any:
        near[0] += lam.size if depth[0] == 0 else 0  # (it recurses on a part of its reads)
        depth[0] += 1
        try:
            return integrate(lam, *args, **kw)
        finally:
            depth[0] -= 1

    expectation._integrate_reads = count
    try:
        for c in calls:
            rm = expectation.ReadModel(**c["rm"])
            expectation.read_cumulants(c["lam"], c["det"], c["off"], rm, **c["kw"])
    finally:
        expectation._integrate_reads = integrate
    return near[0]


def timed(side: Side, calls_path: Path) -> tuple[float, str]:
    """CPU seconds of all the calls on ``side`` (its own process, one thread), and its digest."""
    argv = [sys.executable, "-P", "-c", TIME_SCRIPT, str(calls_path)]
    done = subprocess.run(argv, env=side.env(BENCH_SIM_THREADS="1"), capture_output=True, text=True,
                          cwd=calls_path.parent)
    if done.returncode != 0:
        raise RuntimeError(f"{side.name}: the timed calls exited {done.returncode}: {done.stderr[-2000:]}")
    cpu, digest, package = done.stdout.split()[-3:]
    if side.tree is not None and not package.startswith(str(side.tree)):
        raise RuntimeError(f"{side.name}: imported {package}, not the side's tree {side.tree}")
    return float(cpu), digest


WORKLOADS = {"rig": rig_calls, "dataset": dataset_calls}


def compare(sides: list[Side], name: str, calls: list[dict[str, Any]], tmp: Path, repeat: int) -> None:
    """Time ``calls`` on every side (interleaved); print the sizes, medians, ratio and digests."""
    reads, near = sum(c["lam"].size for c in calls), integrated(calls)
    print(f"  {name}: {len(calls)} calls, {reads:,} reads, {near:,} near a clip (integrated, "
          f"{100 * near / reads:.1f} %)")
    path = tmp / f"{name}_calls.pkl"
    path.write_bytes(pickle.dumps(calls))
    runs: dict[str, list[tuple[float, str]]] = {side.name: [] for side in sides}
    for _ in range(repeat):  # interleaved: A, B, A, B, ...
        for side in sides:
            runs[side.name].append(timed(side, path))
    cpu = {n: median([t for t, _ in got]) for n, got in runs.items()}
    digests = {n: {d for _, d in got} for n, got in runs.items()}
    for side in sides:
        each = ", ".join(f"{t:.2f}" for t, _ in runs[side.name])
        print(f"    {side.name:<22} {cpu[side.name]:6.2f} CPU s (runs: {each}), outputs "
              f"{', '.join(sorted(digests[side.name]))}")
    if len(sides) == 2:
        here, base = (s.name for s in sides)
        print(f"    speed-up, baseline / this checkout: {cpu[base] / cpu[here]:.2f}x; outputs "
              f"{'bit-identical' if digests[here] == digests[base] else 'DIFFER'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="A/B pairs")
    ap.add_argument("--light", type=float, default=448.0, help="the rig's strong spot [W/m^2]")
    ap.add_argument("--workloads", default="rig,dataset", help="comma-separated: rig, dataset")
    add_baseline_args(ap)
    ap.set_defaults(baseline=TRUTH_BASELINE_REV)
    a = ap.parse_args()
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    print(f"read_cumulants of one pass's truth (256 x 256, stages {STAGES}), median of {a.repeat} "
          f"runs per side, interleaved, each in its own process; {load_line()} at the start")
    with tempfile.TemporaryDirectory(prefix="bench_truth_reads_") as tmp:
        for name in a.workloads.split(","):
            compare(sides, name, WORKLOADS[name](a.light, Path(tmp)), Path(tmp), a.repeat)
    print(f"  {load_line()} at the end")


if __name__ == "__main__":
    main()
