"""``bench-sim design SPEC.toml --out DIR`` (and :func:`bench_sim.design`): which stages, rule,
word and timing to use for a camera and a scene, scored on the exact truth.

Plan -> points -> judgement -> chain DR -> outputs:

1. :func:`~bench_sim.workflows.design.tasks.plan_design` reads and checks the spec
   (:mod:`bench_sim.workflows.design.spec`), every point's engine and inputs, the output folder
   and ``--resume``; then the memory and disk are checked. A problem is one line, nothing written.
2. Each point (one value of the non-stage keys) is one all-stage pass with its truth, on which
   every candidate is scored (:func:`~bench_sim.workflows.design.passes.measure_point`): all stage
   pairs of a point cost one pass, not one per pair. The points run on the execution layer
   (:mod:`bench_sim.runtime.execution`: ``--workers`` processes of a local Dask cluster, or
   ``--scheduler``; a design of one point runs in this process unless ``--workers`` says
   otherwise); each finished point is journalled (``points/NNNNNN.json`` and its scores
   ``points/NNNNNN.npz``), so a killed design is finished with ``--resume``.
3. The candidates are judged (:mod:`bench_sim.workflows.design.objectives`): constraints,
   ranking, the Pareto front.
4. The DR through the chain (:func:`~bench_sim.workflows.design.passes.measure_chain`, a
   photon-transfer series per candidate, the expensive part of ``reproduce``) is measured for the
   chosen designs (recommended, runner-up, the configured pair) and, with ``chain_dr = "front"``,
   the pairs on the Pareto front (at most :data:`MAX_CHAIN` of them, best ranked first), each
   journalled in ``chain/NNNNNN.json``.
5. ``candidates.csv`` (+ ``.json``), ``design.nc``, ``plots/`` and ``report.md``, ``design.json``
   and the completion record last.

The folder is written in place (like ``sweep``): without ``--resume`` it must be new, empty or a
finished bench_sim output (whose listed files are replaced); an unfinished design is never
overwritten, and a folder holding anything a design does not write is refused.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import config_sha256
from bench_sim.errors import BenchSimError, note_kept
from bench_sim.io import OUTPUT_MARKER, atomic_path, write_json
from bench_sim.io.folder_lock import folder_lock
from bench_sim.io.ownership import entries, listed_files, remove_listed
from bench_sim.measure.design_scores import word_config
from bench_sim.runtime.execution import (
    TaskOutcome,
    check_workers,
    default_workers,
    open_client,
    run_tasks,
)
from bench_sim.runtime.progress import progress_bar
from bench_sim.sensor.dtdi import frames_needed
from bench_sim.workflows.design.objectives import Choice
from bench_sim.workflows.design.passes import (
    ChainTask,
    PointResult,
    measure_chain,
    measure_point,
    pass_stages,
    point_inputs,
)
from bench_sim.workflows.design.report import write_report
from bench_sim.workflows.design.table import DesignTable, build_table, judge, write_tables
from bench_sim.workflows.design.tasks import (
    QUICK_DR_LEVELS,
    DesignPlan,
    chain_journal,
    file_sha256,
    plan_design,
    points_journal,
    scores_path,
)
from bench_sim.workflows.estimates import estimate_design
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import preflight_tasks

__all__ = ["run_design", "DesignSummary", "MAX_CHAIN", "read_scores"]

#: at most this many front candidates get the DR through the chain (the chosen ones always do)
MAX_CHAIN = 32


@dataclass
class DesignSummary:
    """What :func:`run_design` did: the folder, the points run and skipped, the candidates, the
    recommended design's row (``None``: no feasible candidate) and the wall time [s]."""

    out: Path
    points: int
    ran: list[int]
    skipped: int
    failed: int
    candidates: int
    recommended: dict[str, Any] | None
    wall_s: float
    table: DesignTable | None = field(default=None, repr=False)


def read_scores(path: Path) -> dict[str, np.ndarray]:
    """A point's score columns from its ``.npz``."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _write_scores(path: Path, columns: dict[str, np.ndarray]) -> str:
    """Write a point's score columns atomically; returns the file's SHA-256."""
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in columns.items()})  # type: ignore[arg-type]
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(buf.getvalue())
    return file_sha256(path)


def _point_record(plan: DesignPlan, outcome: TaskOutcome) -> dict[str, Any]:
    """The journal record of a finished point (its scores written first)."""
    p = plan.spec.points[outcome.index]
    rec: dict[str, Any] = {
        "point": outcome.index,
        "values": p.values,
        "config_sha256": config_sha256(p.cfg),
        "design_sha256": plan.sha256,
        "seed": plan.spec.seed,
        "noise": plan.spec.noise,
        "status": "ok" if outcome.ok else "failed",
        "error": outcome.error,
        "wall_s": outcome.wall_s,
        "worker": outcome.worker,
    }
    if outcome.ok:
        res: PointResult = outcome.value
        rec.update(
            scores_sha256=_write_scores(scores_path(plan.out, outcome.index), res.scores.columns),
            candidates=len(res.scores),
            dark_pixels=res.scores.dark_pixels,
            rng_state=res.rng_state,
            stage_mtf50_along={str(m): v for m, v in res.stage_mtf50_along.items()},
            mitsuba_renders=res.mitsuba_renders,
            truth_not_exact=list(res.truth_not_exact),
            timings_s=res.timings_s,
        )
    return rec


def _run_points(plan: DesignPlan, client: Any, records: dict[int, dict[str, Any]], progress: bool) -> None:
    """Run the points still to do; journal each as it arrives. The bar counts the passes' frames
    when they run in this process, the points on a cluster."""
    todo = plan.todo
    journal = points_journal(plan.out)
    here = client is None
    total = sum(frames_needed(t.cfg.lines, pass_stages(t)) for t in todo) if here else len(todo)
    with progress_bar("design: passes", total, "frames" if here else "points", enabled=progress) as bar:

        def done(outcome: TaskOutcome) -> None:
            rec = _point_record(plan, outcome)
            journal.write(rec)
            records[outcome.index] = rec
            if not here:
                bar.advance()

        shared, counting = point_inputs(todo)
        args = [replace(t, count_records=t.index in counting) for t in todo]
        func = functools.partial(measure_point, on_frames=bar.advance) if here else measure_point
        run_tasks(func, args, client=client, indices=[t.index for t in todo], on_result=done, shared=shared,
                  keep_values=False)


def _chain_tasks(
    plan: DesignPlan, table: DesignTable, choice: Choice, records: dict[int, dict[str, Any]]
) -> list[tuple[ChainTask, list[int]]]:
    """The chain DR measurements: per distinct (point, word, pair) the task and its candidates."""
    if plan.spec.chain_dr == "none":
        return []
    c = table.columns
    chosen = [i for i in (choice.recommended, choice.runner_up, choice.reference) if i is not None]
    front: list[int] = []
    if plan.spec.chain_dr == "front":
        order = {i: k for k, i in enumerate(choice.ranked)}
        on = sorted(np.flatnonzero(choice.front), key=lambda i: (order.get(int(i), len(order)), int(i)))
        front = [int(i) for i in on if c["mu_mid"][i] == 0][:MAX_CHAIN]
    groups: dict[tuple[int, int, int, int], list[int]] = {}
    for i in [*chosen, *front]:
        if c["mu_mid"][i]:
            continue
        key = (int(c["point"][i]), int(c["beta_bits"][i]), int(c["mu1"][i]), int(c["mu2"][i]))
        groups.setdefault(key, [])
    for i in range(len(table)):  # every rule of a measured pair shares its chain DR
        key = (int(c["point"][i]), int(c["beta_bits"][i]), int(c["mu1"][i]), int(c["mu2"][i]))
        if key in groups and not c["mu_mid"][i]:
            groups[key].append(i)
    levels = QUICK_DR_LEVELS if plan.spec.quick else 40
    tasks = []
    for n, (key, members) in enumerate(groups.items()):
        point, beta, mu1, mu2 = key
        cfg = plan.spec.points[point].cfg
        tasks.append(
            (
                ChainTask(
                    n, point, beta, mu1, mu2, word_config(cfg, beta), records[point]["rng_state"], levels
                ),
                members,
            )
        )
    return tasks


def _run_chain(
    plan: DesignPlan,
    client: Any,
    table: DesignTable,
    choice: Choice,
    records: dict[int, dict[str, Any]],
    progress: bool,
) -> dict[int, dict[str, Any]]:
    """Measure (or read back, on ``--resume``) the chain DR of the chosen and front pairs; fills
    ``dr_chain_db`` of their candidates. Returns task -> record."""
    tasks = _chain_tasks(plan, table, choice, records)
    journal = chain_journal(plan.out)
    old = {
        (r.get("point"), r.get("beta_bits"), r.get("mu1"), r.get("mu2")): r
        for r in journal.read().values()
        if r.get("design_sha256") == plan.sha256 and r.get("status") == "ok"
    }
    done: dict[int, dict[str, Any]] = {}
    todo = []
    for t, _members in tasks:
        rec = old.get((t.point, t.beta_bits, t.mu1, t.mu2))
        if rec is not None and rec.get("task") == t.task:
            done[t.task] = rec
        else:
            todo.append(t)
    with progress_bar("design: chain DR", len(todo), "pairs", enabled=progress) as bar:

        def finished(outcome: TaskOutcome) -> None:
            t = next(t for t, _ in tasks if t.task == outcome.index)
            rec = {
                "task": t.task,
                "point": t.point,
                "beta_bits": t.beta_bits,
                "mu1": t.mu1,
                "mu2": t.mu2,
                "design_sha256": plan.sha256,
                "status": "ok" if outcome.ok else "failed",
                "error": outcome.error,
                "dr": outcome.value if outcome.ok else None,
            }
            journal.write(rec)
            done[t.task] = rec
            bar.advance()

        if todo:
            run_tasks(measure_chain, todo, client=client, indices=[t.task for t in todo], on_result=finished)
    c = table.columns
    for t, members in tasks:
        dr = (done.get(t.task) or {}).get("dr")
        if dr:
            c["dr_chain_db"][members] = dr["dr_db"]["gamma_hdr"]
            c["dr_chain_db_extrapolated"][members] = dr["dr_db_extrapolated"]["gamma_hdr"]
    return done


def _judge(plan: DesignPlan, records: dict[int, dict[str, Any]]) -> tuple[DesignTable, Choice]:
    """The candidate table of the finished points, judged."""
    ok = {i: r for i, r in records.items() if r["status"] == "ok"}
    scores = {i: read_scores(scores_path(plan.out, i)) for i in ok}
    table = build_table(plan.spec, ok, scores)
    return table, judge(table, plan.spec)


def _meta(
    plan: DesignPlan, status: str, sessions: list[dict[str, Any]], totals: dict[str, Any]
) -> dict[str, Any]:
    """The content of ``design.json``."""
    return provenance(
        plan.spec.base,
        plan.spec.seed,
        kind="design",
        status=status,
        spec=plan.spec.as_dict(),
        design_sha256=plan.sha256,
        sessions=sessions,
        **totals,
    )


def _open_folder(plan: DesignPlan, workers: int | None, scheduler: str | None) -> list[dict[str, Any]]:
    """Make ``DIR`` ready (kept on ``--resume``; else a finished set's listed files removed),
    mark it unfinished, write ``design.json`` (status ``running``); returns the sessions."""
    out = plan.out
    old_sessions: list[dict[str, Any]] = []
    if plan.resume:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            old_sessions = list(json.loads((out / "design.json").read_text()).get("sessions", []))
    elif out.exists() and any(out.iterdir()):
        left = remove_listed(out, listed_files(out) or [])
        if left:
            raise BenchSimError(
                f"--out = {str(out)!r}: {left[0]!r} appeared in the folder meanwhile; it is not "
                "bench_sim's and is kept: move it away or choose a new folder"
            )
    out.mkdir(parents=True, exist_ok=True)
    (out / OUTPUT_MARKER).unlink(missing_ok=True)
    session = {
        "resumed": bool(plan.resume),
        "skipped": len(plan.done),
        "ran": [t.index for t in plan.todo],
        "workers": workers if scheduler is None else None,
        "scheduler": scheduler is not None,
    }
    sessions = [*old_sessions, session]
    write_json(out / "design.json", _meta(plan, "running", sessions, {}))
    return sessions


def _workers(plan: DesignPlan, workers: int | None, scheduler: str | None) -> int | None:
    """``--workers``: as given; by default this process for a design of one point to run, else
    the usable cores."""
    if workers is not None or scheduler is not None:
        return workers
    return 0 if len(plan.todo) <= 1 else default_workers()


def run_design(
    spec_path: str | Path,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    progress: bool = True,
    plots: bool = True,
    on_point: Callable[[dict[str, Any]], None] | None = None,
) -> DesignSummary:
    """``bench-sim design``: plan (every check first), score every candidate, judge, write (module
    docstring).

    Parameters
    ----------
    spec_path
        The design spec (TOML, :mod:`bench_sim.workflows.design.spec`).
    out
        Output folder.
    workers, scheduler
        ``--workers N`` processes of a local Dask cluster (``0``: this process; default: this
        process for one point, else the usable cores), or ``--scheduler tcp://HOST:PORT``.
    resume
        Finish a stopped design in ``out`` (same spec): its finished points and chain DRs are kept.
    progress
        Progress bars (on a terminal) and a summary line.
    plots
        Draw ``plots/``.
    on_point
        Called with each point's journal record as it is written (tests, monitoring).
    """
    check_workers(workers, scheduler)
    t0 = time.perf_counter()
    with folder_lock(Path(out).expanduser().resolve(), "design"):
        plan = plan_design(spec_path, out, resume=resume)
        n_workers = _workers(plan, workers, scheduler)
        _preflight(plan, n_workers, scheduler)
        records: dict[int, dict[str, Any]] = dict(plan.done)
        opened = False
        try:
            with open_client(workers=n_workers, scheduler=scheduler) as client:
                sessions = _open_folder(plan, n_workers, scheduler)
                opened = True
                if plan.todo:
                    _run_points(plan, client, records, progress)
                for i in sorted(records) if on_point is not None else ():
                    on_point(records[i])  # type: ignore[misc]
                table, choice = _judge(plan, records)
                chain = _run_chain(plan, client, table, choice, records, progress) if len(table) else {}
            failed = _write_outputs(plan, table, choice, records, chain, sessions, plots)
        except BaseException as exc:
            if opened:  # while the points run, the cluster closes or the outputs are written
                ok = sum(1 for r in records.values() if r["status"] == "ok")
                note_kept(exc, f"{ok} of {len(plan.tasks)} points finished are kept in {plan.out}; finish "
                               f"with 'bench-sim design {spec_path} --out {plan.out} --resume'")
            raise
    best = table.row(choice.recommended) if choice.recommended is not None else None
    if progress:
        what = (f"recommended {best['stages']} ({best['rule']}, {best['beta_bits']}-bit)" if best
                else "no candidate meets the constraints")
        print(f"  {len(table)} candidates of {len(plan.tasks)} points ({failed} failed): {what} -> "
              f"{plan.out}")
    return DesignSummary(plan.out, len(plan.tasks), [t.index for t in plan.todo], len(plan.done), failed,
                         len(table), best, time.perf_counter() - t0, table)


def _preflight(plan: DesignPlan, n_workers: int | None, scheduler: str | None) -> None:
    """Memory, backend and disk of the points still to do (one line on a problem)."""
    n = len(plan.spec.space.rows())
    preflight_tasks(
        "design", [(t.cfg, (*t.space.stages, t.cfg.sensor.rows)) for t in plan.todo], out=plan.out,
        workers=n_workers, scheduler=scheduler,
        disk_bytes={"journal, tables and report": 64 * 1024 * (len(plan.tasks) + 16),
                    "candidate scores (points/*.npz, candidates.csv, design.nc)": 768 * n * len(plan.tasks)},
        hint="lower --workers, lines or sensor.columns", estimate=estimate_design,
    )


def _write_outputs(plan: DesignPlan, table: DesignTable, choice: Choice, records: dict[int, dict[str, Any]],
                   chain: dict[int, dict[str, Any]], sessions: list[dict[str, Any]], plots: bool) -> int:
    """The tables, plots, report, ``design.json`` and the completion record (last); returns the
    failed points."""
    failed = sum(1 for r in records.values() if r["status"] != "ok")
    totals = {"points": len(plan.tasks), "failed": failed, "candidates": len(table)}
    write_tables(plan.out, table, plan.spec, {"design_sha256": plan.sha256,
                                              **_meta(plan, "complete", sessions, totals)})
    write_report(plan.out, plan.spec, table, choice, records, chain, plots=plots)
    status = "complete" if failed == 0 else "complete_with_failures"
    write_json(plan.out / "design.json", _meta(plan, status, sessions, totals))
    write_json(plan.out / OUTPUT_MARKER, {"command": "design", "design_sha256": plan.sha256, **totals,
                                          "files": entries(plan.out)})
    return failed
