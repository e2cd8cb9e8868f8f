"""One sweep point in a worker: the chain on the point's stream, measured into one flat record.

:func:`measure_point` runs ``simulate``'s pass with its truth, the eq. 11 fusion, the pass
metrics (:mod:`bench_sim.measure.pass_metrics`), the measured dynamic range through the chain
(:mod:`bench_sim.measure.chain_dr`) and the flicker banding per stage.

The dynamic range through the chain is a property of the camera (sensor, timing, DTDI, the
fused stages), not of the lights or the target: it is measured once per distinct camera for the
whole sweep (:func:`point_inputs`: a shared input of the execution layer,
:class:`bench_sim.runtime.execution.Shared`, made by :func:`camera_dr` on the sweep's root
stream ``SeedSequence(seed)``; the points draw from its children), so every point with the same
camera reports the same numbers, whichever worker ran it; its columns are kept on disk
(:mod:`bench_sim.workflows.sweep.camera_store`) for a later sweep of the same camera. The fast
engine's light records are shared the same way: rendered once per distinct scene
(:func:`bench_sim.render.exposures.fast_records`) and installed in the process of each point
that needs them.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.fusion.stage_pair import fuse_stage_words
from bench_sim.io.strict_json import strict_json
from bench_sim.measure.chain_dr import measure_chain_dynamic_range
from bench_sim.measure.fusion_scores import fusion_scores
from bench_sim.measure.pass_metrics import pass_metrics
from bench_sim.measure.sharpness import has_slanted_edges, pass_sharpness
from bench_sim.metrics.banding import folded_cycles_per_line
from bench_sim.pipeline import PassResult, Read, run_pass
from bench_sim.render.exposures import fast_records, records_group
from bench_sim.render.records import LightRecords, install_records
from bench_sim.runtime.execution import Shared, task_seed_sequence, worker_cache
from bench_sim.workflows.sweep import camera_store
from bench_sim.workflows.sweep.bands import banding_rows, stage_banding
from bench_sim.workflows.sweep.light_keys import light_ratio
from bench_sim.workflows.sweep.plan import IMAGES, TRUTH_REGIONS, TRUTH_RULES, PointTask, banding_column
from bench_sim.workflows.sweep.point_images import write_point_images

__all__ = ["measure_point", "point_inputs", "camera_dr", "camera_key"]


def camera_key(cfg: BenchConfig, root_seed: int, dr_levels: int) -> str:
    """What the measured DR depends on: sensor, timing, DTDI, the fused stages, the stream."""
    part = {
        "sensor": cfg.sensor.model_dump(mode="json"),
        "timing": cfg.timing.model_dump(mode="json"),
        "dtdi": cfg.dtdi.model_dump(mode="json"),
        "mu": [cfg.fusion.mu1, cfg.fusion.mu2],
        "seed": root_seed,
        "levels": dr_levels,
    }
    return "sweep-chain-dr:" + json.dumps(part, sort_keys=True)


def camera_dr(arg: tuple[BenchConfig, int, int]) -> dict[str, Any]:
    """The camera columns of the camera of ``(cfg, root_seed, dr_levels)``: its measured dynamic
    range through the chain (:func:`~bench_sim.measure.chain_dr.measure_chain_dynamic_range` on
    ``SeedSequence(root_seed)``), as strict JSON holds them (the point's record does); a shared
    input of the points of that camera. Read from the disk store
    (:mod:`bench_sim.workflows.sweep.camera_store`) when this camera was measured before, else
    measured and stored: the same values either way."""
    cfg, root_seed, dr_levels = arg
    key = camera_key(cfg, root_seed, dr_levels)
    stored = camera_store.load(key)
    if stored is not None:
        return stored
    dr = measure_chain_dynamic_range(
        cfg, np.random.SeedSequence(root_seed), n_levels=dr_levels, columns=min(64, cfg.sensor.columns)
    )
    columns: dict[str, Any] = strict_json(_camera_columns(dr))
    camera_store.save(key, columns)
    return columns


def _camera_dr(cfg: BenchConfig, root_seed: int, dr_levels: int) -> dict[str, Any]:
    """:func:`camera_dr`, cached in this process (a point run without its shared input)."""
    key = camera_key(cfg, root_seed, dr_levels)
    return worker_cache(key, lambda: camera_dr((cfg, root_seed, dr_levels)))


def point_inputs(tasks: list[PointTask]) -> tuple[list[tuple[Shared, ...]], set[int]]:
    """The shared inputs of each point (its light records, then its camera's DR; see the module
    docstring) and the points that count the records' Mitsuba renders (the first point, by
    index, of each record set: the renders are made once for all of them)."""
    shared: list[tuple[Shared, ...]] = []
    first: dict[str, int] = {}
    for t in tasks:
        group = records_group(t.cfg)
        camera = (t.cfg, t.root_seed, t.dr_levels)
        dr = Shared(camera_key(*camera), camera_dr, camera)
        if group is None:
            shared.append((dr,))
            continue
        first[group] = min(first.get(group, t.index), t.index)
        shared.append((Shared("records:" + group, fast_records, t.cfg), dr))
    return shared, set(first.values())


def _renders(setup: Any) -> int:
    """Mitsuba renders a pass's set-up made (0 when the fast engine's records were cached)."""
    return int(setup.info["mitsuba_renders"])


def _camera_columns(dr: Any) -> dict[str, Any]:
    """The camera columns from the chain's measured dynamic range."""
    rec: dict[str, Any] = {f"dr_db_{name}": dr.images[name].dr_db for name in IMAGES}
    rec.update({
        "gain_db_vs_gamma1": dr.gain_over_gamma1_db,
        "gain_db_vs_gamma2": dr.gain_over_gamma2_db,
        "eq15_db": dr.eq15_db,
        "gain_db_vs_gamma2_extrapolated": dr.gain_over_gamma2_extrapolated_db,
        "eq15_error_db": dr.gain_over_gamma2_extrapolated_db - dr.eq15_db,
        "eq15_by_construction": dr.gain_over_gamma2_by_construction,
    })
    return rec


def _scene_columns(pm: Any) -> dict[str, Any]:
    """The scene columns from the pass metrics (:class:`~bench_sim.measure.pass_metrics.PassMetrics`)."""
    omega = {"gamma1": pm.eq18.omega1, "gamma2": pm.eq18.omega2, "gamma_hdr": pm.eq18.omega_hdr}
    rec: dict[str, Any] = {"scene_range_db": pm.scene_range_db}
    rec.update({f"saturated_fraction_{name}": pm.saturated_fraction[name] for name in IMAGES})
    rec.update({f"omega_{name}": omega[name] for name in IMAGES})
    rec.update(eq18_holds=pm.eq18.holds, no_patches=pm.no_patches)
    cap = pm.captured_range_db or {}
    for name in IMAGES:
        rec[f"captured_range_db_{name}"] = cap.get(name)
        rec[f"clipped_fraction_{name}"] = (pm.clipped_fraction or {}).get(name)
    if cap.get("gamma_hdr") is not None and cap.get("gamma1") is not None:
        rec["captured_gain_db_vs_gamma1"] = cap["gamma_hdr"] - cap["gamma1"]
    for which, patch in (("darkest", pm.darkest_patch), ("brightest", pm.brightest_patch)):
        rec[f"{which}_patch"] = patch["patch"] if patch else None
        rec[f"{which}_reflectance"] = patch["reflectance"] if patch else None
        for name in IMAGES:
            rec[f"snr_{which}_{name}"] = patch["snr"][name] if patch else None
    return rec


def _truth_columns(summary: dict[str, Any]) -> dict[str, Any]:
    """Gamma_HDR against its exact truth (:func:`bench_sim.measure.fusion_scores.fusion_scores`)."""
    rec: dict[str, Any] = {}
    for rule in TRUTH_RULES:
        scores = summary["rules"][rule]
        for region in TRUTH_REGIONS:
            for stat in ("bias", "rms"):
                rec[f"truth_{stat}_{rule}_{region}"] = scores["error"][region][stat]
        rec[f"from_clipped_fraction_{rule}"] = scores["from_clipped_fraction"]
    rec["tdi_light_ratio_outside_fraction"] = summary["light_ratio"]["outside_fraction"]
    p99 = summary["light_ratio"]["p99"]
    rec["tdi_light_ratio_p99"] = None if math.isnan(p99) else p99
    return rec


def _banding_columns(task: PointTask, read: Read) -> dict[str, float]:
    """Flicker banding of each flickering light at each stage of the pass (its variables read by
    ``read``; NaN where it does not flicker or emit at this point)."""
    cfg = task.cfg
    rec: dict[str, float] = {}
    for name in task.flicker_lights:
        light = cfg.lights.get(name)
        nu = folded_cycles_per_line(light.flicker_hz, cfg.timing.line_period_s) if light.emits else 0.0
        for m in task.stages:
            amp = float("nan")
            if light.flickers and light.emits:
                amp = stage_banding(cfg, read, m, nu).amplitude  # on the flat-target pixels: no target floor
            rec[banding_column(name, m)] = amp
    return rec


def _sharpness_columns(cfg: BenchConfig, sim: PassResult) -> dict[str, float | None]:
    """MTF50 along and across the track of Gamma1, Gamma2 and Gamma_HDR from the target's
    slanted edges of the pass ``sim`` (:func:`bench_sim.measure.sharpness.pass_sharpness` on its
    arrays); empty (``None``) without them."""
    rec: dict[str, float | None] = {f"mtf50_{d}_{n}": None for d in ("along", "across") for n in IMAGES}
    if not has_slanted_edges(cfg):
        return rec
    sharp = pass_sharpness(sim.read, sim.stages, sim.variables, cfg)
    if sharp is None:  # no whole square in view
        return rec
    for d in ("along", "across"):
        for name, m in (("gamma1", cfg.fusion.mu1), ("gamma2", cfg.fusion.mu2)):
            rec[f"mtf50_{d}_{name}"] = float(sharp.per_stage[sharp.stages.index(m)][d].mtf50_cyc_px)
        if sharp.hdr is not None:
            rec[f"mtf50_{d}_gamma_hdr"] = float(sharp.hdr[d].mtf50_cyc_px)
    return {k: (None if v is not None and math.isnan(v) else v) for k, v in rec.items()}


def measure_point(task: PointTask, *inputs: Any) -> dict[str, Any]:
    """Run the chain for one point and return its flat record
    (:data:`~bench_sim.workflows.sweep.plan.COLUMNS` and banding).

    The pass draws from ``task_seed_sequence(root_seed, stream)``; the camera DR from the root
    ``SeedSequence(root_seed)``. ``inputs`` are the point's shared inputs
    (:func:`point_inputs`: its light records, if any, then its camera's DR); without them the
    records come from this process's cache or are rendered, and the DR is measured once per
    camera in this process. With ``task.count_records`` the point's ``mitsuba_renders`` counts
    the renders that made its shared records.
    """
    cfg = task.cfg
    records = next((x for x in inputs if isinstance(x, LightRecords)), None)
    if records is not None:
        install_records(records)
    dr = next((x for x in inputs if isinstance(x, dict)), None)  # the camera columns
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    rng = np.random.default_rng(task_seed_sequence(task.root_seed, task.stream))
    sim = run_pass(cfg, task.stages, rng, truth=True)
    fused = fuse_stage_words(cfg, sim.stage_dn[mu1], sim.stage_dn[mu2])
    pm = pass_metrics(cfg, sim, fused)
    rec = dict(dr if dr is not None else _camera_dr(cfg, task.root_seed, task.dr_levels))
    rec.update(_scene_columns(pm))
    shared_renders = records.renders if records is not None and task.count_records else 0
    rec["mitsuba_renders"] = _renders(sim.setup) + shared_renders
    lights = cfg.lights
    if lights.strong.emits and lights.weak.emits:
        rec["spot_fill_ratio"] = lights.strong.irradiance_w_m2 / lights.weak.irradiance_w_m2
    rec.update(_truth_columns(fusion_scores(cfg, sim, fused).summary))
    rec.update(_banding_columns(task, sim.read))
    rec.update(_sharpness_columns(cfg, sim))
    if task.ratio is not None:
        rec["light_ratio"] = light_ratio(cfg, task.ratio)
    # the long table points_images.csv: every listed stage and gamma_hdr, with the closed form
    stages = tuple(sorted({*task.banding_stages, mu1, mu2}))
    rec["banding_images"] = banding_rows(task.index, cfg, stages, sim.read, fused)
    if task.images_dir is not None:  # the one step that builds the pass's dataset (xarray)
        write_point_images(task.images_dir, task.index, sim.dataset)
    return rec
