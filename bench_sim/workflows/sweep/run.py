"""``bench-sim sweep SPEC.toml --out DIR``: scenario studies, one simulation pass per point, on Dask.

Plan -> run -> write:

1. :func:`~bench_sim.workflows.sweep.plan.plan_sweep` reads the spec
   (:mod:`bench_sim.workflows.sweep.spec`: every key, value and point config checked), checks
   every point's engine and input files, the output folder and ``--resume``; a problem is one
   line (exit 2) before any point runs, and nothing is written.
2. :func:`run_sweep` runs the points still to do on ``dask.distributed``
   (:mod:`bench_sim.runtime.execution`: a ``LocalCluster`` of ``--workers`` processes, or
   ``--scheduler ADDRESS``). Each point (:func:`~bench_sim.workflows.sweep.point.measure_point`)
   runs the chain on its own stream and returns one flat record. A failed point is recorded
   with its one-line error and the sweep goes on.
3. As each point completes, the client writes its record to the journal ``points/NNNNNN.json``
   (:mod:`bench_sim.runtime.journal`) and rewrites ``points.csv``; at the end ``sweep.nc``,
   ``plots/`` and ``report.md`` (:mod:`bench_sim.workflows.sweep.report`), and the completion
   record last.

Reuse
-----
What the points have in common is made once for the whole sweep, whatever the number of
workers (:func:`~bench_sim.workflows.sweep.point.point_inputs`, shared inputs of the execution
layer): the fast engine's light records once per distinct scene (a light's power or flicker,
the target, the sensor's noise, DTDI or fusion change no record) and the camera's measured
dynamic range once per distinct camera, each as a task of its own that runs beside the others
and is handed to the points that need it; the records, the engine's kernels and the camera's
columns are kept on disk too (:mod:`bench_sim.render.record_store`,
:mod:`bench_sim.render.kernel_store`, :mod:`bench_sim.workflows.sweep.camera_store`), so a
later sweep of the same scene and camera reads them. Worker processes live for the whole sweep, so the
render module's caches (Mitsuba, compiled kernels) serve every point they run. Each point
reports the Mitsuba renders made for it (``mitsuba_renders``: its pass's, plus its shared
records' for the first point, by index, that uses them) and ``sweep.json`` their total.

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
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from bench_sim.config import BenchConfig, config_sha256
from bench_sim.errors import BenchSimError, note_kept
from bench_sim.io import OUTPUT_MARKER, write_json
from bench_sim.io.folder_lock import folder_lock
from bench_sim.io.ownership import entries, listed_files, remove_listed
from bench_sim.io.strict_json import strict_json
from bench_sim.runtime.execution import TaskOutcome, check_workers, open_client, release_client, run_tasks
from bench_sim.runtime.preload import FIGURES, import_modules
from bench_sim.runtime.progress import progress_bar
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import preflight_tasks
from bench_sim.workflows.sweep.plan import (
    CAMERA,
    COLUMNS,
    RUN,
    SCENE,
    PointTask,
    SweepPlan,
    column_docs,
    journal,
    plan_sweep,
    read_points,
    spec_sha256,
)
from bench_sim.workflows.sweep.point import measure_point, point_inputs
from bench_sim.workflows.sweep.report import write_outputs, write_points_csv

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


#: what the outputs are written with (``sweep.nc``: xarray, which asks for Dask's arrays, and netCDF4)
WRITE_MODULES = ("xarray", "dask.array", "netCDF4")


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
    for part in key.split("."):  # sections and fields; named entries (sensor.effects.<name>) by key
        cur = cur[part] if isinstance(cur, dict) else getattr(cur, part)
    return list(cur) if isinstance(cur, tuple) else cur


def _record(plan: SweepPlan, task: PointTask, outcome: TaskOutcome) -> dict[str, Any]:
    """The journal record of a finished point, as strict JSON holds it (a non-finite metric, e.g.
    the SNR of a noise-free patch, is ``None``): the same in memory as read back on ``--resume``."""
    point = plan.spec.points[task.index]
    return strict_json({
        "point": task.index,
        "values": {k: _value_of(point.cfg, k) for k in plan.spec.keys},
        "varied": point.varied,
        "config_sha256": config_sha256(point.cfg),
        "spec_sha256": plan.sha256,  # --resume takes only the records of this spec and seed
        "seed": plan.spec.seed,
        "stream": task.stream,
        "status": "ok" if outcome.ok else "failed",
        "error": outcome.error,
        "wall_s": outcome.wall_s,
        "worker": outcome.worker,
        "metrics": outcome.value if outcome.ok else {},
    })


def _meta(
    plan: SweepPlan, status: str, sessions: list[dict[str, Any]], totals: dict[str, Any]
) -> dict[str, Any]:
    """The content of ``sweep.json``."""
    return provenance(
        plan.spec.base,
        plan.spec.seed,
        covers=[p.cfg for p in plan.spec.points],  # truth_exact only where every point's truth is
        kind="sweep",
        status=status,
        spec=plan.spec.as_dict(),
        spec_sha256=plan.sha256,
        columns={c: {"units": u, "kind": k, "meaning": d} for c, (u, k, d) in column_docs(plan).items()},
        sessions=sessions,
        **totals,
    )


def _preflight(plan: SweepPlan, workers: int | None, scheduler: str | None, plots: bool) -> None:
    """Memory, backend and disk of the points still to do (one line on a problem)."""
    preflight_tasks(
        "sweep",
        [(t.cfg, t.stages) for t in plan.todo],
        out=plan.out,
        workers=workers,
        scheduler=scheduler,
        disk_bytes={
            f"{len(plan.tasks)} points (journal, points.csv, sweep.nc)": len(plan.tasks) * 16 * 1024,
            "plots and report": (len(plan.spec.keys) + 2) * 512 * 1024 if plots else 64 * 1024,
        },
        hint="lower --workers, lines or sensor.columns",
    )


def _open_folder(
    plan: SweepPlan, workers: int | None, scheduler: str | None
) -> tuple[list[dict[str, Any]], dict[int, dict[str, Any]]]:
    """Make ``DIR`` ready (kept on ``--resume``, else the files of the finished set it holds
    removed, nothing else), mark it unfinished and write
    ``sweep.json`` (status ``running``). Returns the sessions and the records already there."""
    out = plan.out
    old_sessions: list[dict[str, Any]] = []
    if plan.resume:  # nothing removed: the plan checked that every entry is this sweep's
        with contextlib.suppress(OSError, ValueError, AttributeError):  # lost or unreadable: rebuilt
            old_sessions = list(json.loads((out / "sweep.json").read_text()).get("sessions", []))
    elif out.exists() and any(out.iterdir()):
        # a finished bench_sim output set (checked by the plan): only the files its record lists go
        left = remove_listed(out, listed_files(out) or [])
        if left:
            raise BenchSimError(f"--out = {str(out)!r}: {left[0]!r} appeared in the folder meanwhile; it is "
                                "not bench_sim's and is kept: move it away or choose a new folder")
    out.mkdir(parents=True, exist_ok=True)
    (out / OUTPUT_MARKER).unlink(missing_ok=True)  # unfinished from here on
    session = {"resumed": bool(plan.resume), "skipped": len(plan.done), "ran": [t.index for t in plan.todo],
               "workers": workers if scheduler is None else None, "scheduler": scheduler is not None}
    sessions = [*old_sessions, session]
    write_json(out / "sweep.json", _meta(plan, "running", sessions, {}))
    # only this sweep's finished points (plan.done): a failed record is recomputed
    return sessions, dict(plan.done)


def _run_points(
    plan: SweepPlan, client: Any, records: dict[int, dict[str, Any]], progress: bool,
    on_point: Callable[[dict[str, Any]], None] | None, plots: bool,
) -> None:
    """Run the points still to do; journal each record, rewrite ``points.csv`` as it arrives.
    While the points run on workers, this process imports what the outputs are written with."""
    todo = plan.todo
    points = journal(plan.out)
    with progress_bar("sweep", len(todo), "points", enabled=progress) as bar:

        def done(outcome: TaskOutcome) -> None:
            rec = _record(plan, plan.tasks[outcome.index], outcome)
            records[rec["point"]] = rec
            points.write(rec)
            write_points_csv(plan.out, plan, records)
            if on_point is not None:
                on_point(rec)
            bar.advance()

        shared, counting = point_inputs(todo)
        args = [replace(t, count_records=t.index in counting) for t in todo]
        run_tasks(measure_point, args, client=client, indices=[t.index for t in todo], on_result=done,
                  shared=shared, meanwhile=lambda: import_modules(WRITE_MODULES + (FIGURES if plots else ())))


def _totals(plan: SweepPlan, records: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """Points, ok, failed and Mitsuba renders of the sweep (``sweep.json``, completion record)."""
    ok = sum(1 for r in records.values() if r["status"] == "ok")
    renders = sum(
        int(r["metrics"].get("mitsuba_renders") or 0) for r in records.values() if r["status"] == "ok"
    )
    return {
        "points": len(plan.tasks),
        "ok": ok,
        "failed": len(records) - ok,
        "mitsuba_renders": renders,
        "mitsuba_renders_per_point": renders / ok if ok else None,
    }


def _run_and_write(
    plan: SweepPlan, workers: int | None, scheduler: str | None, progress: bool, plots: bool,
    on_point: Callable[[dict[str, Any]], None] | None, spec_path: str | Path,
) -> dict[int, dict[str, Any]]:
    """Run the points still to do and write the outputs; an interruption (Ctrl-C, SIGTERM, a
    lost cluster) says what is kept and how to resume."""
    todo = plan.todo
    records: dict[int, dict[str, Any]] = {}
    opened = False
    # the cluster is reached (or started) before anything is written: an unreachable scheduler
    # leaves no output behind
    cluster = open_client(workers=workers, scheduler=scheduler) if todo else contextlib.nullcontext()
    try:
        with cluster as client:
            sessions, records = _open_folder(plan, workers, scheduler)
            opened = True
            if todo:
                _run_points(plan, client, records, progress, on_point, plots)
            release_client(client)  # the cluster closes while the outputs are written
            totals = _totals(plan, records)
            write_outputs(plan.out, plan, records, sessions, plots=plots)
            write_json(plan.out / "sweep.json", _meta(plan, "complete" if totals["failed"] == 0 else
                                                      "complete_with_failures", sessions, totals))
        # the completion record once the cluster is closed: last, as before
        write_json(plan.out / OUTPUT_MARKER, {"command": "sweep", "spec_sha256": plan.sha256, **totals,
                                              "files": entries(plan.out)})
    except BaseException as exc:
        if opened:  # while the points run, the cluster closes or the outputs are written
            ok = sum(1 for r in records.values() if r["status"] == "ok")
            note_kept(exc, f"{ok} of {len(plan.tasks)} points finished are kept in {plan.out}; finish with "
                           f"'bench-sim sweep {spec_path} --out {plan.out} --resume'")
        raise
    return records


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
    progress
        Show a progress bar (on a terminal) and a summary line.
    plots
        Draw ``plots/`` (``sweep.nc`` holds everything to draw them later).
    on_point
        Called in this process with each point's record as it is written.
    """
    check_workers(workers, scheduler)
    # one writer per folder: held from before the folder is read until its last file is written
    with folder_lock(Path(out).expanduser().resolve(), "sweep"):
        plan = plan_sweep(spec_path, out, resume=resume)
        _preflight(plan, workers, scheduler, plots)
        t0 = time.perf_counter()
        records = _run_and_write(plan, workers, scheduler, progress, plots, on_point, spec_path)
    totals = _totals(plan, records)
    ok, failed, renders, todo = totals["ok"], totals["failed"], totals["mitsuba_renders"], plan.todo
    summary = SweepSummary(plan.out, len(plan.tasks), [t.index for t in todo], len(plan.done), ok, failed,
                           renders, time.perf_counter() - t0, records)
    if progress:
        print(f"  {ok} of {len(plan.tasks)} points ok ({len(todo)} run, {len(plan.done)} skipped), "
              f"{failed} failed, {renders} Mitsuba renders -> {plan.out}")
    return summary
