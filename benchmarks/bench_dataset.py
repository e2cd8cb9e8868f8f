"""Throughput, size on disk and memory of ``bench-sim dataset`` at 256 x 256 with stages {10, 80}.

The spec is ``scenes/datasets/example.toml`` (spot and fill levels, sync error and target drawn
per sample) with its number of samples changed. For 1 and 2 workers of a local Dask cluster
(the execution layer's ``open_client``), it:

1. warms the workers up with a 2-sample dataset (imports, Mitsuba's JIT),
2. times a dataset of ``--samples`` samples: samples per minute, and the 2-worker speed-up,
3. on the 2-worker cluster, makes a dataset of 3 x ``--samples`` samples next and compares the
   workers' peak resident memory (``ru_maxrss``) after each run: flat in the number of samples
   when a worker holds one sample at a time. The client's peak is printed too.

``--rss-samples K`` instead makes K samples one after the other in this process (what a worker
does) and prints its resident memory every 8 samples.

Bytes per sample: the size of ``data.zarr`` (Zarr v3, Zstandard) over the samples, beside the
uncompressed size of a sample's arrays. Timings are wall-clock on whatever else the machine runs:
the load average before each timed run is printed with it.

Usage: python benchmarks/bench_dataset.py [--samples 8] [--keep DIR] [--rss-samples K]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path

from bench_sim.config import SCENES_DIR
from bench_sim.runtime.execution import open_client
from bench_sim.workflows.dataset.run import bytes_per_sample, run_dataset

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


def _worker_peak_mib(client) -> list[float]:
    peaks = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    return [kib / 1024 for kib in peaks.values()]


def _run(client, spec: Path, out: Path) -> float:
    t0 = time.perf_counter()
    run = run_dataset(spec, out, scheduler=client.scheduler.address)
    assert run.done, run.failed
    return time.perf_counter() - t0


def _rss_series(samples: int) -> None:
    """Resident memory of one process making ``samples`` samples of the example in a row."""
    from bench_sim.workflows.dataset.run import SampleTask, make_sample
    from bench_sim.workflows.dataset.spec import load_spec, sample_streams

    with tempfile.TemporaryDirectory() as tmp:
        spec = load_spec(_spec(Path(tmp), samples))
        for i in range(samples):
            cfg = spec.sample_config(spec.draw(i), i)
            make_sample(SampleTask(i, cfg, spec.stages, sample_streams(spec.seed, i)[1]))
            if i % 8 == 7 or i == samples - 1:
                pages = int(Path("/proc/self/statm").read_text().split()[1])
                mib = pages * os.sysconf("SC_PAGE_SIZE") / 2**20
                print(f"after {i + 1:4d} samples: resident {mib:6.0f} MiB", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--keep", type=Path, default=None, help="keep the datasets in this folder")
    ap.add_argument("--rss-samples", type=int, default=0, help="only: memory of one process over K samples")
    a = ap.parse_args()
    if a.rss_samples:
        _rss_series(a.rss_samples)
        return
    tmp = Path(tempfile.mkdtemp(prefix="bench_dataset_")) if a.keep is None else a.keep
    tmp.mkdir(parents=True, exist_ok=True)
    n = a.samples
    warm, spec, spec_more = _spec(tmp, 2), _spec(tmp, n), _spec(tmp, 3 * n)
    rate: dict[int, float] = {}
    try:
        for workers in (1, 2):
            with open_client(workers=workers) as client:
                _run(client, warm, tmp / f"warm_{workers}")
                load = os.getloadavg()[0]
                wall = _run(client, spec, tmp / f"data_{workers}")
                rate[workers] = 60.0 * n / wall
                print(f"{workers} worker(s): {n} samples in {wall:6.1f} s = {rate[workers]:5.2f} samples/min "
                      f"(load average before: {load:.1f} on {os.cpu_count()} cores)")
                if workers == 2:
                    peak_n = _worker_peak_mib(client)
                    _run(client, spec_more, tmp / "data_more")
                    peak_3n = _worker_peak_mib(client)
        print(f"speed-up 2 / 1 workers: {rate[2] / rate[1]:.2f}")
        store = tmp / "data_2" / "data.zarr"
        on_disk = sum(f.stat().st_size for f in store.rglob("*") if f.is_file())
        raw = bytes_per_sample(2, 256, 256, True)
        print(f"bytes per sample on disk: {on_disk / n / 2**20:.2f} MiB "
              f"(uncompressed arrays {raw / 2**20:.2f} MiB, ratio {on_disk / n / raw:.2f})")
        print("peak resident memory per worker [MiB]: after "
              f"{n} samples {', '.join(f'{p:.0f}' for p in peak_n)}; after {n} + {3 * n} samples "
              f"{', '.join(f'{p:.0f}' for p in peak_3n)}")
        client_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"peak resident memory of the client (writes every sample): {client_peak:.0f} MiB")
    finally:
        if a.keep is None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
