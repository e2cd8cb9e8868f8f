"""``bench-sim render``: exposures of a pass to ``DIR/exposures.exr`` and ``DIR/meta.json``.

``exposures.exr`` holds one channel ``photons`` of height ``frames * rows`` and width
``columns``: frame ``k`` is rows ``k*M .. k*M + M - 1``. The header attribute ``bench_sim``
(JSON) carries the shape ``[frames, rows, columns]``, units and provenance; :func:`read_exposures`
returns the ``(frames, rows, columns)`` array. ``ground_truth.exr`` holds the target reflectance
behind each complete output line (channel ``reflectance``, shape ``(frames - rows + 1, columns)``).
``meta.json`` is the same metadata plus the run's own figures: ``wall_s`` (its wall time) and
``mitsuba_renders`` (renders made; fewer when the process had the records cached).
The three files are written as one output set (:func:`bench_sim.io.output_set`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.io import output_set, read_exr, write_exr, write_json
from bench_sim.render.exposures import render_photons
from bench_sim.render.texture import ground_truth_reflectance
from bench_sim.runtime.provenance import provenance, render_provenance
from bench_sim.workflows.estimates import estimate_render
from bench_sim.workflows.preflight import check_seed, preflight

__all__ = ["run_render", "read_exposures"]

UNITS = {
    "photons": "mean photons per pixel per frame (in-band, at sensor.wavelength_m)",
    "reflectance": "diffuse reflectance 0..1 (ground truth)",
    "frame_k_time_s": "k * timing.line_period_s",
}


def run_render(
    cfg: BenchConfig, *, frames: int, engine: str | None, seed: int, out: Path
) -> dict[str, Any]:
    """Render ``frames`` line periods and write ``exposures.exr``, ``ground_truth.exr`` and
    ``meta.json`` into ``out`` as one output set. Returns the metadata.

    Everything is checked first (frames, engine, seed, output folder, memory and disk, target
    image, backend); ``meta.json``'s ``wall_s`` is the only wall-clock time (the EXR files of two
    runs with the same config and seed are identical)."""

    if isinstance(frames, bool) or not isinstance(frames, int | np.integer) or frames < 1:
        raise BenchSimError(f"--frames = {frames!r}: must be an integer >= 1")
    if engine is not None and engine not in ("fast", "reference"):
        raise BenchSimError(f"--engine = {engine!r}: allowed 'fast' or 'reference'")
    seed = check_seed(seed)
    out = preflight(cfg, out=out, estimate=estimate_render(cfg, int(frames), engine))
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    photons, setup = render_photons(cfg, frames, rng, engine=engine)
    K, M, N = photons.shape
    lines = max(K - M + 1, 0)
    truth = ground_truth_reflectance(cfg, setup.geom, setup.grid.panel, lines) if lines else None
    meta = provenance(
        cfg,
        seed,
        kind="exposures",
        shape=[K, M, N],
        layout="frame k = image rows k*M .. k*M+M-1",
        units=UNITS,
        render=render_provenance(setup.info),
        backend=setup.backend.as_dict(),
    )
    record = {"command": "render", **{k: meta[k] for k in ("version", "seed", "config_sha256")}}
    with output_set(out, record) as tmp:
        write_exr(tmp / "exposures.exr", {"photons": photons.reshape(K * M, N)}, meta)
        if truth is not None:
            tmeta = dict(meta, kind="ground_truth", shape=[lines, N], layout="scene line j = row j")
            write_exr(tmp / "ground_truth.exr", {"reflectance": truth}, tmeta)
        # the run's own figures, in meta.json only: its wall time and the Mitsuba renders it made
        meta["wall_s"] = round(time.perf_counter() - t0, 3)
        meta["mitsuba_renders"] = setup.info.get("mitsuba_renders")
        write_json(tmp / "meta.json", meta)
    return meta


def read_exposures(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """Read ``exposures.exr``: photons (frames, rows, columns) and its metadata."""
    channels, meta = read_exr(path)
    if "photons" not in channels or "shape" not in meta:
        raise BenchSimError(f"{path}: not a bench_sim exposures file (no 'photons' channel/shape)")
    K, M, N = meta["shape"]
    return channels["photons"].reshape(K, M, N), meta
