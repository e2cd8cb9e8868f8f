"""``bench-sim render``: exposures of a pass to ``DIR/exposures.exr`` and ``DIR/meta.json``.

``exposures.exr`` holds one channel ``photons`` of height ``frames * rows`` and width
``columns``: frame ``k`` is rows ``k*M .. k*M + M - 1``. The header attribute ``bench_sim``
(JSON) carries the shape ``[frames, rows, columns]``, units and provenance; :func:`read_exposures`
returns the ``(frames, rows, columns)`` array. ``ground_truth.exr`` holds the target reflectance
behind each complete output line (channel ``reflectance``, shape ``(frames - rows + 1, columns)``).
``meta.json`` is the same metadata plus the run's own figures: ``wall_s`` (its wall time) and
``mitsuba_renders`` (renders made; fewer when the process had the records cached).
The three files are written as one output set (:func:`bench_sim.io.output_set`).

**Which stage the truth is for.** ``ground_truth.exr`` is the material at ``y = j delta`` behind
line ``j``: stage 1's (sensor row 0 in frame ``j``). Stage ``m``'s line ``j`` sums rows
``i < m`` in frames ``j + i``; row ``i`` sits one object pixel ``p`` further back than row 0 and
the drum moves ``delta = p (1 + e)`` per line period (``e`` = ``timing.sync_error``), so row ``i``
sees the material at ``j delta + i e p`` and the stage's truth is centred

    s_m = e (m - 1) / (2 (1 + e))   lines                                  (stage_truth_shift_lines)

further along the track (and smeared over ``|e| (m - 1)`` object pixels): 0 at perfect sync,
1.88 lines for stage 80 at ``e = 0.05``. The header (``aligned_for_stage``, ``sync_error``,
``stage_shift_lines`` for stage 1, the fused pair ``mu1``, ``mu2`` and the top stage ``M``),
``meta.json`` (``ground_truth``) and the printed summary say so; every stage's exact truth
(footprints from the rig geometry, sync error included) is ``simulate``'s ``reflectance``.
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
from bench_sim.runtime.provenance import render_provenance
from bench_sim.workflows.estimates import estimate_render
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed, preflight

__all__ = [
    "run_render", "read_exposures", "stage_truth_shift_lines", "ground_truth_alignment", "summary_line",
]

UNITS = {
    "photons": "mean photons per pixel per frame (in-band, at sensor.wavelength_m)",
    "reflectance": "diffuse reflectance 0..1 (ground truth)",
    "frame_k_time_s": "k * timing.line_period_s",
}


def stage_truth_shift_lines(sync_error: float, stage: int) -> float:
    """Where stage ``m``'s truth sits relative to ``ground_truth.exr`` (stage 1's) [lines,
    positive = further along the track]: ``e (m - 1) / (2 (1 + e))`` (module docstring).

    Parameters
    ----------
    sync_error
        ``timing.sync_error`` ``e`` (the drum moves ``1 + e`` object pixels per line period).
    stage
        DTDI stage ``m >= 1``.
    """
    e = float(sync_error)
    return e * (int(stage) - 1) / (2.0 * (1.0 + e))


def ground_truth_alignment(cfg: BenchConfig) -> dict[str, Any]:
    """The ``ground_truth.exr`` alignment record: the stage it is for (1), the sync error, and the
    shift of stage 1, ``mu1``, ``mu2`` and ``M``'s truth from it [lines]."""
    e = float(cfg.timing.sync_error)
    stages = sorted({1, cfg.fusion.mu1, cfg.fusion.mu2, cfg.sensor.rows})
    return {
        "aligned_for_stage": 1,
        "sync_error": e,
        "stage_shift_lines": {str(m): round(stage_truth_shift_lines(e, m), 6) for m in stages},
        "stage_shift_formula": "e (m - 1) / (2 (1 + e)) lines further along the track",
        "every_stage": "bench-sim simulate --stages ...: the exact reflectance of each stage",
    }


def summary_line(meta: dict[str, Any], out: Path) -> str:
    """The one line ``render`` prints: the files and which stage the truth is aligned for."""
    k, m, n = meta["shape"]
    gt = meta.get("ground_truth")
    if gt is None:
        truth = "no ground_truth.exr (fewer frames than sensor rows)"
    else:
        shifts = gt["stage_shift_lines"]
        top = max(shifts, key=int)
        truth = (f"ground_truth.exr ({gt['lines']} lines) is stage 1's; at sync error "
                 f"{gt['sync_error']:g} stage {top}'s truth is {shifts[top]:.2f} lines further "
                 "along (simulate gives every stage's)")
    return f"wrote {out}/exposures.exr ({k} frames x {m} rows x {n} columns), {truth}, meta.json"


def run_render(
    cfg: BenchConfig, *, frames: int, engine: str | None, seed: int, out: Path
) -> dict[str, Any]:
    """Render ``frames`` line periods and write ``exposures.exr``, ``ground_truth.exr`` and
    ``meta.json`` into ``out`` as one output set; print :func:`summary_line`. Returns the metadata.

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
            align = ground_truth_alignment(cfg)
            tmeta = dict(meta, kind="ground_truth", shape=[lines, N], layout="scene line j = row j",
                         **align)
            write_exr(tmp / "ground_truth.exr", {"reflectance": truth}, tmeta)
            meta["ground_truth"] = {"lines": lines, **align}
        # the run's own figures, in meta.json only: its wall time and the Mitsuba renders it made
        meta["wall_s"] = round(time.perf_counter() - t0, 3)
        meta["mitsuba_renders"] = setup.info.get("mitsuba_renders")
        write_json(tmp / "meta.json", meta)
    print(summary_line(meta, out))
    return meta


def read_exposures(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """Read ``exposures.exr``: photons (frames, rows, columns) and its metadata."""
    channels, meta = read_exr(path)
    if "photons" not in channels or "shape" not in meta:
        raise BenchSimError(f"{path}: not a bench_sim exposures file (no 'photons' channel/shape)")
    K, M, N = meta["shape"]
    return channels["photons"].reshape(K, M, N), meta
