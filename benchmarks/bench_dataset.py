"""Samples per minute of ``bench-sim dataset`` at 256 x 256 with stages {10, 80} on 2 Dask workers,
this checkout against the main branch before the speed work (A/B, :mod:`baseline`), and the time
to the first finished sample.

The spec is ``scenes/datasets/example.toml`` (the package's copy: spot and fill levels, sync
error and target drawn per sample) with its number of samples changed to ``--samples``. Both
sides make it as a separate ``bench-sim dataset --workers 2`` process, as a user would, in pairs
interleaved A, B, A, B (``--repeat`` pairs), so a change of the machine's load hits both alike.
Per side: the median wall time and CPU time (user + system of the process and its workers),
samples per minute (samples / median wall), and the time from the process's start to the first
sample's record (``samples/NNNNNNNN.json``, its modification time). The ratio is this checkout's
samples per minute over the baseline's. Bytes per sample on disk (Zarr v3, Zstandard) are
printed beside the uncompressed size.

``--rss-samples K`` instead makes K samples one after the other in this process (what a worker
does) and prints its resident memory every 8 samples.

Usage: python benchmarks/bench_dataset.py [--samples 6] [--repeat 2] [--workers 2]
       [--baseline REV | --no-baseline] [--keep DIR] [--rss-samples K]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline import Side, add_baseline_args, load_line, paired, print_rates, workflow_run  # noqa: E402

from bench_sim.config import SCENES_DIR  # noqa: E402
from bench_sim.workflows.dataset.reader import read_records  # noqa: E402
from bench_sim.workflows.dataset.run import SampleTask, bytes_per_sample, make_sample  # noqa: E402
from bench_sim.workflows.dataset.spec import load_spec, sample_streams  # noqa: E402

EXAMPLE = SCENES_DIR / "datasets" / "example.toml"


def _spec(folder: Path, samples: int) -> Path:
    """The example spec with ``samples`` samples, its relative paths made absolute."""
    text = EXAMPLE.read_text()
    text = text.replace('base = "../paper_rig.toml"', f'base = "{SCENES_DIR / "paper_rig.toml"}"')
    text = text.replace('pattern = "../targets/*.png"', f'pattern = "{SCENES_DIR / "targets"}/*.png"')
    text = text.replace("samples = 16", f"samples = {samples}")
    path = folder / f"spec_{samples}.toml"
    path.write_text(text)
    return path


def _rss_series(samples: int) -> None:
    """Resident memory of one process making ``samples`` samples of the example in a row."""
    with tempfile.TemporaryDirectory() as tmp:
        spec = load_spec(_spec(Path(tmp), samples))
        for i in range(samples):
            values = spec.draw(i)
            scene = {k.removeprefix("scene."): v for k, v in values.items() if k.startswith("scene.")}
            cfg = spec.sample_config(values, i)
            make_sample(SampleTask(i, cfg, spec.stages, sample_streams(spec.seed, i)[1], None, scene))
            if i % 8 == 7 or i == samples - 1:
                pages = int(Path("/proc/self/statm").read_text().split()[1])
                mib = pages * os.sysconf("SC_PAGE_SIZE") / 2**20
                print(f"after {i + 1:4d} samples: resident {mib:6.0f} MiB", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=2, help="A/B pairs")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, default=None, help="keep the datasets in this folder")
    ap.add_argument("--rss-samples", type=int, default=0, help="only: memory of one process over K samples")
    add_baseline_args(ap)
    a = ap.parse_args()
    if a.rss_samples:
        _rss_series(a.rss_samples)
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench_dataset_")) if a.keep is None else a.keep
    tmp.mkdir(parents=True, exist_ok=True)
    n = a.samples
    spec = _spec(tmp, n)
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    first: dict[str, list[float]] = {s.name: [] for s in sides}

    def run(side: Side, i: int) -> tuple[float, float]:
        def check(out: Path) -> None:
            done = sum(1 for r in read_records(out).values() if r.get("status") == "complete")
            if done != n:
                raise RuntimeError(f"{side.name}: {done} of {n} samples complete")

        return workflow_run(sides, side, i, tmp, "dataset", spec, a.workers, "samples", "sample", first,
                            check)

    print(f"dataset of {n} samples of the example spec (256 x 256, stages 10 and 80), {a.workers} workers, "
          f"each run a bench-sim process; {load_line()}", flush=True)
    try:
        times = paired(sides, run, a.repeat)
        print_rates(sides, times, first, n, "samples")
        store = tmp / "a_0" / "data.zarr"
        on_disk = sum(f.stat().st_size for f in store.rglob("*") if f.is_file())
        raw = bytes_per_sample(load_spec(spec))
        print(f"  bytes per sample on disk (this checkout): {on_disk / n / 2**20:.2f} MiB "
              f"(uncompressed arrays {raw / 2**20:.2f} MiB, ratio {on_disk / n / raw:.2f})")
    finally:
        if a.keep is None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
