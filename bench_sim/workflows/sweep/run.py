"""``bench-sim sweep SPEC.toml --out DIR``: scenario studies, one simulation pass per point, on Dask.

Plan -> run -> write:

1. :func:`plan_sweep` reads the spec (:mod:`bench_sim.workflows.sweep.spec`: every key,
   value and point config checked), checks every point's engine and input files, the output
   folder and ``--resume``; a problem is one line (exit 2) before any point runs, and nothing
   is written.
2. :func:`run_sweep` runs the points still to do on ``dask.distributed``
   (:mod:`bench_sim.runtime.execution`: a ``LocalCluster`` of ``--workers`` processes, or
   ``--scheduler ADDRESS``). Each point (:func:`measure_point`) runs the chain on its own
   stream -- ``simulate``'s pass with its truth, the eq. 11 fusion, the pass metrics
   (:mod:`bench_sim.measure.pass_metrics`), the measured dynamic range through the chain
   (:mod:`bench_sim.measure.chain_dr`) and the flicker banding per stage -- and returns one
   flat record. A failed point is recorded with its one-line error and the sweep goes on.
3. As each point completes, the client writes its record to ``points/NNNNNN.json`` and
   rewrites ``points.csv``; at the end ``sweep.nc``, ``plots/`` and ``report.md``
   (:mod:`bench_sim.workflows.sweep.report`), and the completion record last.

Reuse
-----
The dynamic range through the chain is a property of the camera (sensor, timing, DTDI, the
fused stages), not of the lights or the target: each worker measures it once per camera
(:func:`bench_sim.runtime.execution.worker_cache`) on the sweep's root stream
``SeedSequence(seed)`` (the points draw from its children), so every point with the same
camera reports the same numbers, whichever worker ran it. Worker processes live for the whole
sweep, so the render module's caches (Mitsuba scenes, compiled kernels, light records) serve
every point they run; each point reports the Mitsuba renders its pass made
(``mitsuba_renders``) and ``sweep.json`` their total.

Output folder
-------------
``DIR`` is written in place while the sweep runs, so a killed sweep can be finished with
``--resume`` (same spec; points with status ``ok`` are skipped, missing and failed ones run).
Without ``--resume``, ``DIR`` must be new, empty, or a finished bench_sim output (replaced);
an unfinished sweep is never overwritten.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig, config_sha256
from bench_sim.errors import BenchSimError
from bench_sim.workflows.sweep.spec import SweepSpec, load_spec

__all__ = [
    "COLUMNS",
    "CAMERA",
    "SCENE",
    "RUN",
    "PointTask",
    "SweepPlan",
    "SweepSummary",
    "measure_point",
    "plan_sweep",
    "run_sweep",
    "read_points",
    "spec_sha256",
]

CAMERA, SCENE, RUN = "camera", "scene", "run"
IMAGES = (("gamma1", "gamma1"), ("gamma2", "gamma2"), ("hdr", "gamma_hdr"))

#: The metric columns of a point: name -> (units, kind, meaning). ``camera``: a property of the
#: sensor, timing, DTDI and fusion settings (the same under any light); ``scene``: depends on
#: the lights and the target as much as on the camera; ``run``: how the point ran.
COLUMNS: dict[str, tuple[str, str, str]] = {
    "dr_db_gamma1": ("dB", CAMERA, "measured DR of Gamma1 through the chain (EMVA 1288)"),
    "dr_db_gamma2": ("dB", CAMERA, "measured DR of Gamma2 through the chain (EMVA 1288)"),
    "dr_db_hdr": ("dB", CAMERA, "measured DR of Gamma_HDR through the chain (EMVA 1288)"),
    "gain_db_vs_gamma1": ("dB", CAMERA, "DR(Gamma_HDR) - DR(Gamma1)"),
    "gain_db_vs_gamma2": ("dB", CAMERA, "DR(Gamma_HDR) - DR(Gamma2)"),
    "eq15_db": ("dB", CAMERA, "eq. 15: 20 lg(mu2 / mu1)"),
    "gain_db_vs_gamma2_extrapolated": ("dB", CAMERA, "gain over Gamma2 with the extrapolated "
                                       "saturation points (the clip points eq. 15 is about)"),
    "eq15_error_db": ("dB", CAMERA, "gain over Gamma2 (extrapolated saturation) minus eq. 15"),
    "eq15_by_construction": ("1", CAMERA, "both stages clip on the output word with one offset: "
                             "the gain over Gamma2 is eq. 15 by construction"),
    "scene_range_db": ("dB", SCENE, "range of the wedge as lit: 20 lg(brightest / darkest step)"),
    "captured_range_db_gamma1": ("dB", SCENE, "range of the wedge steps Gamma1 renders (SNR >= 3, "
                                 "under half clipped)"),
    "captured_range_db_gamma2": ("dB", SCENE, "range of the wedge steps Gamma2 renders"),
    "captured_range_db_hdr": ("dB", SCENE, "range of the wedge steps Gamma_HDR renders"),
    "captured_gain_db_vs_gamma1": ("dB", SCENE, "captured range of Gamma_HDR minus that of Gamma1 (in "
                                   "steps of the wedge)"),
    "saturated_fraction_gamma1": ("1", SCENE, "pixels of Gamma1 at the word's top"),
    "saturated_fraction_gamma2": ("1", SCENE, "pixels of Gamma2 at the word's top"),
    "saturated_fraction_hdr": ("1", SCENE, "pixels of Gamma_HDR taken from a clipped Gamma1"),
    "clipped_fraction_gamma1": ("1", SCENE, "pixels of Gamma1 clipped anywhere: a read at full well or "
                                "the ADC top, or the word at its top"),
    "clipped_fraction_gamma2": ("1", SCENE, "pixels of Gamma2 clipped anywhere in the chain"),
    "clipped_fraction_hdr": ("1", SCENE, "pixels of Gamma_HDR clipped in the stage they come from"),
    "darkest_patch": ("1", SCENE, "the wedge step with the lowest Gamma_HDR"),
    "darkest_reflectance": ("1", SCENE, "its reflectance"),
    "snr_darkest_gamma1": ("1", SCENE, "spatial SNR of the darkest step in Gamma1"),
    "snr_darkest_gamma2": ("1", SCENE, "spatial SNR of the darkest step in Gamma2"),
    "snr_darkest_hdr": ("1", SCENE, "spatial SNR of the darkest step in Gamma_HDR"),
    "brightest_patch": ("1", SCENE, "the wedge step with the highest Gamma_HDR"),
    "brightest_reflectance": ("1", SCENE, "its reflectance"),
    "snr_brightest_gamma1": ("1", SCENE, "spatial SNR of the brightest step in Gamma1 (empty: over half "
                             "of it clipped)"),
    "snr_brightest_gamma2": ("1", SCENE, "spatial SNR of the brightest step in Gamma2 (empty: clipped)"),
    "snr_brightest_hdr": ("1", SCENE, "spatial SNR of the brightest step in Gamma_HDR (empty: clipped)"),
    "omega_gamma1": ("1", SCENE, "eq. 17 omega of Gamma1"),
    "omega_gamma2": ("1", SCENE, "eq. 17 omega of Gamma2"),
    "omega_hdr": ("1", SCENE, "eq. 17 omega of Gamma_HDR"),
    "eq18_holds": ("1", SCENE, "eq. 18: omega(HDR) < min(omega1, omega2)"),
    "spot_fill_ratio": ("1", SCENE, "lights.strong / lights.weak irradiance (empty unless both emit)"),
    "no_patches": ("1", SCENE, "why the patch metrics are empty (no wedge in view)"),
    "mitsuba_renders": ("1", RUN, "Mitsuba renders this point's pass made"),
}
#: Banding columns (one per flickering light and stage): ``banding_<light>_stage_<m>``.
BANDING_DOC = ("1", SCENE, "flicker banding along the track: amplitude at the light's frequency "
               "relative to the mean, of the stage's illumination profile")


def banding_column(light: str, stage: int) -> str:
    return f"banding_{light}_stage_{stage:03d}"


@dataclass(frozen=True)
class PointTask:
    """Everything a worker needs for one point (picklable)."""

    index: int
    cfg: BenchConfig
    root_seed: int
    stream: int
    stages: tuple[int, ...]
    dr_levels: int
    flicker_lights: tuple[str, ...]


def _camera_key(cfg: BenchConfig, root_seed: int, dr_levels: int) -> str:
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


def _camera_dr(cfg: BenchConfig, root_seed: int, dr_levels: int) -> Any:
    from bench_sim.measure.chain_dr import measure_chain_dynamic_range
    from bench_sim.runtime.execution import worker_cache

    return worker_cache(
        _camera_key(cfg, root_seed, dr_levels),
        lambda: measure_chain_dynamic_range(
            cfg, np.random.SeedSequence(root_seed), n_levels=dr_levels, columns=min(64, cfg.sensor.columns)
        ),
    )


def _renders(setup: Any) -> int:
    """Mitsuba renders a pass's set-up made (0 when the fast engine's records were cached)."""
    return int(setup.info["mitsuba_renders"])


def measure_point(task: PointTask) -> dict[str, Any]:
    """Run the chain for one point and return its flat record (:data:`COLUMNS` and banding).

    The pass draws from ``task_seed_sequence(root_seed, stream)``; the camera DR from the root
    ``SeedSequence(root_seed)``, cached per camera in the worker.
    """
    from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
    from bench_sim.measure.pass_metrics import pass_metrics
    from bench_sim.metrics.banding import banding_amplitude, folded_cycles_per_line, illumination_profile
    from bench_sim.runtime.execution import task_seed_sequence
    from bench_sim.sensor.model import stage_offset_dn
    from bench_sim.workflows.simulate import run_pass

    cfg = task.cfg
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    rng = np.random.default_rng(task_seed_sequence(task.root_seed, task.stream))
    sim = run_pass(cfg, task.stages, rng, truth=True)
    offsets = (stage_offset_dn(cfg.sensor, cfg.dtdi, mu1), stage_offset_dn(cfg.sensor, cfg.dtdi, mu2))
    fused = fuse_dtdi_hdr_eq11(
        sim.stage_dn[mu1], sim.stage_dn[mu2], mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=offsets
    )
    pm = pass_metrics(cfg, sim, fused)
    dr = _camera_dr(cfg, task.root_seed, task.dr_levels)
    rec: dict[str, Any] = {
        "dr_db_gamma1": dr.images["gamma1"].dr_db,
        "dr_db_gamma2": dr.images["gamma2"].dr_db,
        "dr_db_hdr": dr.images["hdr"].dr_db,
        "gain_db_vs_gamma1": dr.gain_over_gamma1_db,
        "gain_db_vs_gamma2": dr.gain_over_gamma2_db,
        "eq15_db": dr.eq15_db,
        "gain_db_vs_gamma2_extrapolated": dr.gain_over_gamma2_extrapolated_db,
        "eq15_error_db": dr.gain_over_gamma2_extrapolated_db - dr.eq15_db,
        "eq15_by_construction": dr.gain_over_gamma2_by_construction,
        "scene_range_db": pm.scene_range_db,
        "saturated_fraction_gamma1": pm.saturated_fraction["gamma1"],
        "saturated_fraction_gamma2": pm.saturated_fraction["gamma2"],
        "saturated_fraction_hdr": pm.saturated_fraction["gamma_hdr"],
        "omega_gamma1": pm.eq18.omega1,
        "omega_gamma2": pm.eq18.omega2,
        "omega_hdr": pm.eq18.omega_hdr,
        "eq18_holds": pm.eq18.holds,
        "no_patches": pm.no_patches,
        "mitsuba_renders": _renders(sim.setup),
    }
    cap = pm.captured_range_db or {}
    for col, key in IMAGES:
        rec[f"captured_range_db_{col}"] = cap.get(key)
        rec[f"clipped_fraction_{col}"] = (pm.clipped_fraction or {}).get(key)
    if cap.get("gamma_hdr") is not None and cap.get("gamma1") is not None:
        rec["captured_gain_db_vs_gamma1"] = cap["gamma_hdr"] - cap["gamma1"]
    for which, patch in (("darkest", pm.darkest_patch), ("brightest", pm.brightest_patch)):
        rec[f"{which}_patch"] = patch["patch"] if patch else None
        rec[f"{which}_reflectance"] = patch["reflectance"] if patch else None
        for col, key in IMAGES:
            rec[f"snr_{which}_{col}"] = patch["snr"][key] if patch else None
    lights = cfg.lights
    if lights.strong.emits and lights.weak.emits:
        rec["spot_fill_ratio"] = lights.strong.irradiance_w_m2 / lights.weak.irradiance_w_m2
    ds = sim.dataset
    for name in task.flicker_lights:
        light = lights.get(name)
        nu = folded_cycles_per_line(light.flicker_hz, cfg.timing.line_period_s) if light.emits else 0.0
        for m in task.stages:
            amp = float("nan")
            if light.flickers and light.emits:
                profile = illumination_profile(
                    ds["photons"].sel(stage=m).values, ds["reflectance"].sel(stage=m).values
                )
                amp = banding_amplitude(profile, nu)
            rec[banding_column(name, m)] = amp
    return rec


# --- plan ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SweepPlan:
    """A checked sweep: spec, tasks, output folder and what is already done."""

    spec: SweepSpec
    out: Path
    tasks: tuple[PointTask, ...]
    done: dict[int, dict[str, Any]]
    resume: bool
    sha256: str
    columns: tuple[str, ...]

    @property
    def todo(self) -> list[PointTask]:
        return [t for t in self.tasks if t.index not in self.done]


def spec_sha256(spec: SweepSpec) -> str:
    """Hash of what the points compute: the spec and every point's resolved config."""
    from bench_sim.io import sha256_text

    body = {k: v for k, v in spec.as_dict().items() if k != "path"}
    body["configs"] = [config_sha256(p.cfg) for p in spec.points]
    return sha256_text(json.dumps(body, sort_keys=True, default=str))


def _point_stages(cfg: BenchConfig, flicker: bool) -> tuple[int, ...]:
    """Stages of a point's pass: the fused pair, and stage 1 when a light flickers (banding)."""
    return tuple(sorted({cfg.fusion.mu1, cfg.fusion.mu2} | ({1} if flicker else set())))


JOURNAL = "points"


def read_points(out: str | Path) -> dict[int, dict[str, Any]]:
    """The point records of a sweep folder (``points/NNNNNN.json``): index -> record."""
    folder = Path(out) / JOURNAL
    records = {}
    if folder.is_dir():
        for f in sorted(folder.glob("[0-9]*.json")):
            rec = json.loads(f.read_text())
            records[int(rec["point"])] = rec
    return records


def _unfinished_sweep(out: Path) -> bool:
    from bench_sim.io import OUTPUT_MARKER

    return (out / "sweep.json").is_file() and not (out / OUTPUT_MARKER).is_file()


def plan_sweep(spec_path: str | Path, out: str | Path, *, resume: bool = False) -> SweepPlan:
    """Check everything before any point runs (see the module docstring); raises
    :class:`~bench_sim.errors.BenchSimError` with one line on the first problem."""
    from bench_sim.io import check_output_dir
    from bench_sim.render.engines import check_fast_engine_valid
    from bench_sim.workflows.simulate import check_inputs

    spec = load_spec(spec_path)
    for p in spec.points:
        where = f"sweep spec {spec.path} point {p.index}"
        try:
            if p.cfg.render.engine == "fast":
                check_fast_engine_valid(p.cfg)
            check_inputs(p.cfg)
        except BenchSimError as exc:
            raise BenchSimError(f"{where}: {str(exc).splitlines()[0]}") from None
    out = Path(out).expanduser().resolve()
    sha = spec_sha256(spec)
    done: dict[int, dict[str, Any]] = {}
    if resume and out.is_dir() and any(out.iterdir()):
        meta_path = out / "sweep.json"
        if not meta_path.is_file():
            raise BenchSimError(f"--out = {str(out)!r}: --resume needs a sweep folder (no sweep.json there)")
        old = json.loads(meta_path.read_text())
        if old.get("spec_sha256") != sha:
            raise BenchSimError(
                f"--out = {str(out)!r}: holds a sweep of another spec or base config "
                f"(spec_sha256 {str(old.get('spec_sha256'))[:12]} != {sha[:12]}): --resume needs the "
                "same spec"
            )
        done = {i: r for i, r in read_points(out).items() if r.get("status") == "ok"}
    elif _unfinished_sweep(out):
        raise BenchSimError(
            f"--out = {str(out)!r}: holds an unfinished sweep: add --resume to finish it, or choose "
            "another folder"
        )
    else:
        check_output_dir(out)
    flicker = tuple(sorted({n for p in spec.points for n, light in p.cfg.lights.items() if light.flickers}))
    quick_levels = 24 if spec.quick else 40
    tasks = tuple(
        PointTask(
            index=p.index,
            cfg=p.cfg,
            root_seed=spec.seed,
            stream=0 if spec.noise == "common" else p.index,
            stages=_point_stages(p.cfg, bool(flicker)),
            dr_levels=quick_levels,
            flicker_lights=flicker,
        )
        for p in spec.points
    )
    stages = sorted({m for t in tasks for m in t.stages})
    columns = (*COLUMNS, *(banding_column(n, m) for n in flicker for m in stages))
    return SweepPlan(spec, out, tasks, done, resume, sha, columns)


# --- run --------------------------------------------------------------------------------------


@dataclass
class SweepSummary:
    """What :func:`run_sweep` did."""

    out: Path
    points: int
    ran: list[int]
    skipped: int
    ok: int
    failed: int
    mitsuba_renders: int
    wall_s: float
    records: dict[int, dict[str, Any]] = field(repr=False, default_factory=dict)


def _value_of(cfg: BenchConfig, key: str) -> Any:
    cur: Any = cfg
    for part in key.split("."):
        cur = getattr(cur, part)
    return list(cur) if isinstance(cur, tuple) else cur


def _record(plan: SweepPlan, task: PointTask, outcome: Any) -> dict[str, Any]:
    point = plan.spec.points[task.index]
    rec: dict[str, Any] = {
        "point": task.index,
        "values": {k: _value_of(point.cfg, k) for k in plan.spec.keys},
        "varied": point.varied,
        "config_sha256": config_sha256(point.cfg),
        "seed": plan.spec.seed,
        "stream": task.stream,
        "status": "ok" if outcome.ok else "failed",
        "error": outcome.error,
        "wall_s": outcome.wall_s,
        "worker": outcome.worker,
        "metrics": outcome.value if outcome.ok else {},
    }
    return rec


def _write_journal(out: Path, rec: dict[str, Any]) -> None:
    from bench_sim.io import write_json

    write_json(out / JOURNAL / f"{rec['point']:06d}.json", rec)


def _meta(
    plan: SweepPlan, status: str, sessions: list[dict[str, Any]], totals: dict[str, Any]
) -> dict[str, Any]:
    from bench_sim.runtime.provenance import provenance

    return provenance(
        plan.spec.base,
        plan.spec.seed,
        kind="sweep",
        status=status,
        spec=plan.spec.as_dict(),
        spec_sha256=plan.sha256,
        columns={c: {"units": u, "kind": k, "meaning": d} for c, (u, k, d) in _column_docs(plan).items()},
        sessions=sessions,
        **totals,
    )


def _column_docs(plan: SweepPlan) -> dict[str, tuple[str, str, str]]:
    return {c: COLUMNS.get(c, BANDING_DOC) for c in plan.columns}


def run_sweep(
    spec_path: str | Path,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    progress: bool = True,
    plots: bool = True,
    on_point: Callable[[dict[str, Any]], None] | None = None,
) -> SweepSummary:
    """``bench-sim sweep``: plan (every check first), run the points still to do on Dask, write.

    Parameters
    ----------
    spec_path
        The sweep spec (TOML, :mod:`bench_sim.workflows.sweep.spec`).
    out
        Output folder (see the module docstring).
    workers, scheduler
        ``--workers N`` processes of a local cluster (default: the usable cores; ``0``: in this
        process), or ``--scheduler tcp://HOST:PORT`` of a running cluster.
    resume
        Skip the points already finished in ``out`` (same spec).
    plots
        Draw ``plots/`` (``sweep.nc`` holds everything to draw them later).
    on_point
        Called in this process with each point's record as it is written.
    """
    from bench_sim.io import OUTPUT_MARKER, write_json
    from bench_sim.runtime.execution import open_client, run_tasks
    from bench_sim.workflows.preflight import preflight_tasks
    from bench_sim.workflows.sweep.report import write_outputs, write_points_csv

    if workers is not None and scheduler is not None:
        raise BenchSimError(
            "--workers and --scheduler: give one of them (--scheduler uses that cluster's workers)"
        )
    if workers is not None and workers < 0:
        raise BenchSimError(f"--workers = {workers}: must be >= 0 (0 runs in this process)")
    plan = plan_sweep(spec_path, out, resume=resume)
    out = plan.out
    preflight_tasks(
        "sweep",
        [(t.cfg, t.stages) for t in plan.todo],
        out=out,
        workers=workers,
        scheduler=scheduler,
        disk_bytes={
            f"{len(plan.tasks)} points (journal, points.csv, sweep.nc)": len(plan.tasks) * 16 * 1024,
            "plots and report": (len(plan.spec.keys) + 2) * 512 * 1024 if plots else 64 * 1024,
        },
        hint="lower --workers, lines or sensor.columns",
    )
    t0 = time.perf_counter()
    todo = plan.todo
    # the cluster is reached (or started) before anything is written: an unreachable scheduler
    # leaves no output behind
    with open_client(workers=workers, scheduler=scheduler) if todo else contextlib.nullcontext() as client:
        old_sessions: list[dict[str, Any]] = []
        if resume and (out / "sweep.json").is_file():
            old_sessions = json.loads((out / "sweep.json").read_text()).get("sessions", [])
        elif out.exists() and any(out.iterdir()):
            shutil.rmtree(out)  # a finished bench_sim output set (checked): replaced by this run
        out.mkdir(parents=True, exist_ok=True)
        (out / OUTPUT_MARKER).unlink(missing_ok=True)  # unfinished from here on
        session = {"resumed": bool(resume), "skipped": len(plan.done), "ran": [t.index for t in todo],
                   "workers": workers if scheduler is None else None, "scheduler": scheduler is not None}
        sessions = [*old_sessions, session]
        write_json(out / "sweep.json", _meta(plan, "running", sessions, {}))
        records = read_points(out) if resume else {}
        records.update(plan.done)

        def done(outcome: Any) -> None:
            task = plan.tasks[outcome.index]
            rec = _record(plan, task, outcome)
            records[task.index] = rec
            _write_journal(out, rec)
            write_points_csv(out, plan, records)
            if on_point is not None:
                on_point(rec)

        indices = [t.index for t in todo]
        if todo and progress:
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            columns = (TextColumn("[bold]sweep"), BarColumn(),
                       TextColumn("{task.completed}/{task.total} points"), TimeElapsedColumn())
            with Progress(*columns) as bar:
                tid = bar.add_task("points", total=len(todo))

                def done_bar(outcome: Any) -> None:
                    done(outcome)
                    bar.update(tid, advance=1)

                run_tasks(measure_point, todo, client=client, indices=indices, on_result=done_bar)
        elif todo:
            run_tasks(measure_point, todo, client=client, indices=indices, on_result=done)
    ok = sum(1 for r in records.values() if r["status"] == "ok")
    failed = len(records) - ok
    renders = sum(
        int(r["metrics"].get("mitsuba_renders") or 0) for r in records.values() if r["status"] == "ok"
    )
    totals = {
        "points": len(plan.tasks),
        "ok": ok,
        "failed": failed,
        "mitsuba_renders": renders,
        "mitsuba_renders_per_point": renders / ok if ok else None,
    }
    write_outputs(out, plan, records, sessions, plots=plots)
    write_json(out / "sweep.json", _meta(plan, "complete" if failed == 0 else "complete_with_failures",
                                         sessions, totals))
    write_json(out / OUTPUT_MARKER, {"command": "sweep", "spec_sha256": plan.sha256, **totals})
    summary = SweepSummary(out, len(plan.tasks), [t.index for t in todo], len(plan.done), ok, failed, renders,
                           time.perf_counter() - t0, records)
    if progress:
        print(f"  {ok} of {len(plan.tasks)} points ok ({len(todo)} run, {len(plan.done)} skipped), "
              f"{failed} failed, {renders} Mitsuba renders -> {out}")
    return summary

