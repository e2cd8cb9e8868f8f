"""The tasks of a design in a worker: one point's pass and its candidates' scores, and one
candidate's dynamic range through the chain.

:func:`measure_point` runs ``simulate``'s pass of the point's bench with its truth at every
candidate stage and the sensor's last row (the pass exposes every sensor row, as ``simulate
--stages all`` does, so a stage's words do not depend on which other stages are candidates, nor
does the darkest region), scores every candidate on
it (:func:`bench_sim.measure.design_scores.score_candidates`) and, when the design reports the
sharpness, measures the MTF50 along the track per candidate stage on a noise-free companion
pass with slanted edges (:func:`bench_sim.workflows.reproduce.stage_mtf.measure_stage_mtf`, as
``reproduce`` does). It returns the state of the point's random generator after the pass: the
chain's DR of a candidate draws from there (:func:`measure_chain`), as ``reproduce``'s does, so
the configured pair's numbers are ``reproduce``'s for the same seed and size.

Streams: with ``noise = "common"`` every point draws from ``numpy.random.default_rng(seed)``
(the root seed itself, as ``reproduce --seed`` and ``simulate --seed`` do: the points differ by
their settings, not by their noise); with ``"independent"`` point ``i`` from
:func:`bench_sim.runtime.execution.task_seed_sequence` ``(seed, i)``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.measure.chain_dr import measure_chain_dynamic_range
from bench_sim.measure.design_scores import PassScores, score_candidates
from bench_sim.pipeline import run_pass
from bench_sim.render.exposures import fast_records, records_group
from bench_sim.render.records import LightRecords, install_records
from bench_sim.runtime.execution import Shared, task_seed_sequence
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.workflows.design.tasks import PointTask
from bench_sim.workflows.reproduce.stage_mtf import measure_stage_mtf

__all__ = [
    "PointResult",
    "ChainTask",
    "measure_point",
    "measure_chain",
    "point_inputs",
    "point_generator",
    "pass_stages",
    "CHAIN_COLUMNS",
]

#: width of the chain's DR images [columns] (narrower sensors: their width), as reproduce's
CHAIN_COLUMNS = 64


@dataclass(frozen=True)
class PointResult:
    """What :func:`measure_point` returns.

    Attributes
    ----------
    index
        The point.
    scores
        Its candidates' scores (:class:`~bench_sim.measure.design_scores.PassScores`).
    rng_state
        The state of the point's generator after the pass (``bit_generator.state``, JSON-ready).
    stage_mtf50_along
        Stage -> MTF50 along the track [cycles/px] (``None``: not measured, no edge or clipped).
    mitsuba_renders
        Mitsuba renders of the pass (and of its shared records, for the first point using them).
    truth_not_exact
        Why the truth is not exact for the sensor's chain (empty: exact).
    timings_s
        Seconds per step: the pass, the scores, the sharpness.
    """

    index: int
    scores: PassScores
    rng_state: dict[str, Any]
    stage_mtf50_along: dict[int, float | None] = field(default_factory=dict)
    mitsuba_renders: int = 0
    truth_not_exact: tuple[str, ...] = ()
    timings_s: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ChainTask:
    """One DR measurement through the chain (picklable): journal index, the candidate's point,
    word and stages, the point's bench at that word, the generator state to draw from and the
    lit levels of the series."""

    task: int
    point: int
    beta_bits: int
    mu1: int
    mu2: int
    cfg: BenchConfig
    rng_state: dict[str, Any]
    n_levels: int


def point_generator(root_seed: int, stream: int | None) -> np.random.Generator:
    """A point's generator (module docstring): the root seed's own (``stream = None``) or
    task ``stream``'s."""
    return np.random.default_rng(root_seed if stream is None else task_seed_sequence(root_seed, stream))


def point_inputs(tasks: list[PointTask]) -> tuple[list[tuple[Shared, ...]], set[int]]:
    """The shared inputs of each point (the fast engine's light records, once per scene for the
    whole run) and the points that count their Mitsuba renders (the first of each scene)."""
    shared: list[tuple[Shared, ...]] = []
    first: dict[str, int] = {}
    for t in tasks:
        group = records_group(t.cfg)
        if group is None:
            shared.append(())
            continue
        first[group] = min(first.get(group, t.index), t.index)
        shared.append((Shared("records:" + group, fast_records, t.cfg),))
    return shared, set(first.values())


def _stage_mtf(cfg: BenchConfig, seed: int, stages: tuple[int, ...]) -> dict[int, float | None]:
    """MTF50 along the track per stage on the noise-free companion pass (``None``: not measured)."""
    res = measure_stage_mtf(cfg, seed, stages)
    if res.sharpness is None:
        return dict.fromkeys(stages)
    vals = dict(zip(res.stages, (float(v) for v in res.mtf50("along")), strict=True))
    return {m: (None if math.isnan(vals[m]) else vals[m]) for m in stages}


def pass_stages(task: PointTask) -> tuple[int, ...]:
    """The stages of a point's pass, each with its truth: every candidate stage and the sensor's
    last row (every row exposed, as ``simulate --stages all`` exposes them; the darkest region is
    the darkest light per row over the whole window)."""
    return tuple(sorted({*task.space.stages, task.cfg.sensor.rows}))


def measure_point(
    task: PointTask, *inputs: Any, on_frames: Callable[[int], None] | None = None
) -> PointResult:
    """One point: the pass, its candidates' scores and the sharpness per stage (module docstring).
    ``inputs``: its shared light records, if any; ``on_frames``: called with the frames of each
    rendered chunk (a progress bar, in this process)."""
    records = next((x for x in inputs if isinstance(x, LightRecords)), None)
    if records is not None:
        install_records(records)
    cfg, space = task.cfg, task.space
    rng = point_generator(task.root_seed, task.stream)
    t0 = time.perf_counter()
    sim = run_pass(cfg, pass_stages(task), rng, truth=True, on_frames=on_frames)
    state = dict(rng.bit_generator.state)
    t1 = time.perf_counter()
    scores = score_candidates(cfg, sim.dataset, space)
    renders = int(sim.setup.info["mitsuba_renders"])
    del sim
    t2 = time.perf_counter()
    mtf = _stage_mtf(cfg, task.root_seed, space.stages) if task.sharpness else {}
    timings = {"pass": t1 - t0, "scores": t2 - t1, "sharpness": time.perf_counter() - t2}
    shared = records.renders if records is not None and task.count_records else 0
    return PointResult(
        task.index,
        scores,
        state,
        mtf,
        renders + shared,
        tuple(sensor_chain(cfg.sensor).not_exact),
        {k: round(v, 3) for k, v in timings.items()},
    )


def measure_chain(task: ChainTask) -> dict[str, Any]:
    """The DR of ``Gamma1``, ``Gamma2`` and ``Gamma_HDR`` of one pair through the chain
    (:func:`bench_sim.measure.chain_dr.measure_chain_dynamic_range`, eq. 11's fusion, as
    ``reproduce`` measures it), drawing from the point's generator where its pass stopped."""
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = task.rng_state
    chain = measure_chain_dynamic_range(
        task.cfg,
        rng,
        mu1=task.mu1,
        mu2=task.mu2,
        n_levels=task.n_levels,
        columns=min(CHAIN_COLUMNS, task.cfg.sensor.columns),
    )
    return {
        "dr_db": chain.dr_db,
        "dr_db_extrapolated": {k: v.dr_db_extrapolated for k, v in chain.images.items()},
        "gain_db_vs_gamma1": chain.gain_over_gamma1_db,
        "gain_db_vs_gamma2": chain.gain_over_gamma2_db,
        "model_dr_db": dict(chain.model_dr_db),
        "pedestal_dn": chain.pedestal_dn,
    }
