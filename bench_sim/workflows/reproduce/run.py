"""``bench-sim reproduce``: the paper's experiment end to end.

Render the default rig (all frames of one pass) -> EMVA 1288 sensor -> DTDI (every Fig. 3 stage
from the same pass) -> fusion at ``mu1``, ``mu2`` (eq. 11) -> ``Gamma_TRA`` -> metrics (Table 1 /
eq. 16-18, eq. 15, measured dynamic range through the whole chain) -> figures and report.

Outputs (``results/paper`` by default): ``fig3_stages.png``, ``fig4_hdr.png``, ``gamma1.tiff``,
``gamma2.tiff`` (16-bit), ``gamma_hdr.exr`` (channels ``Y`` = Gamma_HDR [DN, stage-mu2 units] and
``source`` = the stage each pixel came from), ``gamma_tra.png``, ``table1.csv``, ``metrics.json``,
``report.md``, ``snr_vs_signal.png`` (SNR of Gamma1, Gamma2, Gamma_HDR versus signal from the
photon-transfer series through the chain), ``gamma_hdr_error.png`` and ``tdi_light_ratio.png``
(Gamma_HDR against its exact truth, :mod:`bench_sim.measure.fusion_scores`),
``mtf50_vs_stage.png`` and ``.csv`` (MTF50 along and across the track per stage, from a
companion pass with slanted edges:
:mod:`bench_sim.workflows.reproduce.stage_mtf`). Every file carries the config, seed and version.

Two threads: while the pass runs, a :class:`~bench_sim.runtime.parallel.Lane` beside it measures
the whole-chain DR (on its own random stream, so the numbers are those of the steps in order);
after it, the lane runs the sharpness's companion pass and draws some figures while the pass's
metrics are computed (:mod:`bench_sim.workflows.reproduce.writing`). With
``BENCH_SIM_THREADS=1`` every step runs in order, with the same files.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import QUICK_OVERRIDES, BenchConfig, quick_config
from bench_sim.errors import BenchSimError
from bench_sim.fusion.common import FusionResult
from bench_sim.fusion.stage_pair import fuse_stage_words, stage_offsets_dn
from bench_sim.fusion.tonemap import quantize_display, tone_map
from bench_sim.io import output_set, write_json
from bench_sim.measure.chain_dr import ChainDR, measure_chain_dynamic_range
from bench_sim.measure.fusion_scores import fusion_scores
from bench_sim.measure.pass_metrics import PassMetrics, pass_metrics, patch_slices
from bench_sim.measure.uniform_field import measurement_pedestal_dn
from bench_sim.metrics.dynamic_range import dr_increase_eq15_db, stage_pairs_for_db
from bench_sim.pipeline import PassResult, run_pass
from bench_sim.render.exposures import release
from bench_sim.rig.geometry import rig_geometry
from bench_sim.rig.target import make_panel
from bench_sim.runtime.allocator import give_back, large_blocks_mapped
from bench_sim.runtime.parallel import Lane
from bench_sim.runtime.progress import progress_bar
from bench_sim.runtime.provenance import render_provenance
from bench_sim.sensor.model import (
    QUANTIZATION_VAR_DN2,
    dark_noise_e,
    stage_saturation_photons,
    stage_snr1_photons,
)
from bench_sim.workflows.estimates import estimate_reproduce
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed, preflight
from bench_sim.workflows.reproduce import writing
from bench_sim.workflows.reproduce.figures import Box
from bench_sim.workflows.reproduce.report import write_report, write_table1
from bench_sim.workflows.reproduce.result import (
    PAPER,
    DynamicRangeResult,
    ReproduceResult,
    RunRecord,
    RunShape,
    RunTimings,
    SceneResult,
    SeedsResult,
    Table1Result,
    TruthResult,
)
from bench_sim.workflows.reproduce.seeds import check_seeds, headline_numbers, seed_spread
from bench_sim.workflows.reproduce.stage_mtf import measure_stage_mtf, sharpness_result, write_stage_mtf
from bench_sim.workflows.reproduce.truth_figures import write_truth_figures
from bench_sim.workflows.reproduce.writing import snr_figure, start_image_files

__all__ = [
    "run_reproduce", "check_reproducible", "quick_config", "PAPER", "FIG3_STAGES", "QUICK_OVERRIDES"
]

FIG3_STAGES: tuple[int, ...] = tuple(range(5, 101, 5))

#: Width of the whole-chain DR measurement's images [columns] (narrower sensors: their width).
CHAIN_DR_COLUMNS = 64
#: ``--quick``: lit levels of the whole-chain DR measurement's series (the default otherwise).
QUICK_DR_LEVELS = 24
#: The pass's variables the reproduction reads (its metrics, fusion scores and figures): every
#: stage's words and, of ``mu1`` and ``mu2``, the truth without ``mean_dn`` and ``noise_std_dn``
#: (and their read cumulants, not computed); no image variable (it fuses the words itself).
PASS_VARIABLES_READ = ("dn", "photons", "linear_dn", "reflectance", "clipped")
#: Bits of the stage images' TIFF files.
TIFF_BITS = 16
#: The steps of ``metrics.json``'s ``timings_s``, in this order (``metrics`` and ``sharpness``
#: partly run beside the pass: busy seconds)
TIMED_STEPS = ("render_setup", "render_frames", "sensor_dtdi", "pass_wall", "fusion", "metrics", "sharpness",
               "write")

class _Timer:
    """Seconds per step, added up from any thread (the lane's steps are busy times)."""

    def __init__(self, steps: tuple[str, ...] = ()) -> None:
        self.steps: dict[str, float] = dict.fromkeys(steps, 0.0)  # this order, whoever ends first
        self._lock = threading.Lock()

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.steps[name] = self.steps.get(name, 0.0) + seconds

    @contextlib.contextmanager
    def timed(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - t0)


def _box(panel: Any, cfg: BenchConfig, name: str, half: str, lines: int) -> tuple[int, int, int, int]:
    u0, u1, v0, v1 = panel.element_box(name, half)
    off = cfg.sensor.columns / 2.0 - cfg.target.panel_columns / 2.0
    return (
        max(int(u0), 0),
        min(int(math.ceil(u1)), lines),
        max(int(v0 + off), 0),
        min(int(math.ceil(v1 + off)), cfg.sensor.columns),
    )


def _inset_boxes(panel: Any, cfg: BenchConfig, lines: int) -> tuple[Box, Box]:
    """Fig. 4's insets: the lower (darkest) half of the wedge under the fill alone, and the bar
    group under the spot."""
    wl0, wl1, wc0, wc1 = _box(panel, cfg, "wedge", "right", lines)
    inset = max((wc1 - wc0) // 10, 1)
    dark_box = ((wl0 + wl1) // 2, wl1, wc0 + inset, wc1 - inset)
    return dark_box, _box(panel, cfg, "vbars", "left", lines)


def check_reproducible(cfg: BenchConfig) -> None:
    """Refuse, before anything is rendered, a config whose images cannot show what the
    reproduction measures: the paper target (``target.layout = "paper"``) with a wedge step of
    each half and both Fig. 4 insets (the dark wedge, the bar group) in the ``lines`` x
    ``sensor.columns`` image, stage words that fit its 16-bit TIFF files, and a word wide
    enough for the whole-chain DR measurement's pedestal. Raises :class:`BenchSimError` (one
    line) naming what to change."""
    t = cfg.target
    if t.layout != "paper":
        raise BenchSimError(
            f"target.layout = {t.layout!r}: reproduce measures the paper target's wedge and bars; "
            "use target.layout = 'paper' (bench-sim simulate takes any target)"
        )
    if cfg.dtdi.beta_bits > TIFF_BITS:
        raise BenchSimError(
            f"dtdi.beta_bits = {cfg.dtdi.beta_bits}: reproduce writes gamma1/gamma2 as {TIFF_BITS}-bit "
            f"TIFF; use beta_bits <= {TIFF_BITS} (bench-sim simulate writes any word)"
        )
    ped = measurement_pedestal_dn(cfg, (cfg.fusion.mu1, cfg.fusion.mu2))  # the DR measurement's word
    _check_dr_measurable(cfg, ped)
    geom = rig_geometry(cfg)
    panel = make_panel(t, 2 * math.pi * geom.radius_m / geom.object_pixel_m)
    lines, cols = cfg.lines, cfg.sensor.columns
    patches = patch_slices(panel, geom, cfg, lines)
    dark, bright = _inset_boxes(panel, cfg, lines)
    halves = all(any(k.startswith(f"wedge_{h}") for k in patches) for h in ("left", "right"))
    if halves and all(b[1] - b[0] >= 2 and b[3] - b[2] >= 2 for b in (dark, bright)):
        return
    full = max(int(math.ceil(panel.element_box("vbars", "left")[1] * geom.object_pixel_m / geom.delta_m)), 1)
    raise BenchSimError(
        f"lines = {lines}, sensor.columns = {cols}: the image does not show the paper target's wedge "
        f"steps and bar group (target.panel_lines = {t.panel_lines}, panel_columns = "
        f"{t.panel_columns}); raise lines to at least {full} or lower target.panel_lines, and keep "
        "sensor.columns at least target.panel_columns"
    )


def _check_dr_measurable(cfg: BenchConfig, pedestal_dn: float) -> None:
    """The whole-chain DR needs, for stages ``mu1`` and ``mu2``, an SNR = 1 point below
    saturation (model of :mod:`bench_sim.sensor.model`): temporal dark noise the ADC can see
    (above its rounding step when it rounds) and a saturation above that point."""
    s, t = cfg.sensor, cfg.timing.t_int_s
    noise_dn = s.conversion_gain_dn_per_e * dark_noise_e(s, t)
    if noise_dn**2 < (QUANTIZATION_VAR_DN2 if s.quantization else 1e-12):
        raise BenchSimError(
            f"sensor: the dark signal has {noise_dn:.3g} DN rms of temporal noise per read (read noise "
            f"{s.read_noise_e if s.read_noise else 0} e-, dark current {s.dark_current_e_s} e-/s, "
            f"K = {s.conversion_gain_dn_per_e} DN/e-), below the ADC's rounding: reproduce's dynamic "
            "range has no SNR = 1 point to measure; raise the read noise or K"
        )
    for m in (cfg.fusion.mu1, cfg.fusion.mu2):
        sat = stage_saturation_photons(
            s, t, m, beta_bits=cfg.dtdi.beta_bits, subtract_black=cfg.dtdi.subtract_black,
            pedestal_dn=pedestal_dn,
        )
        snr1 = stage_snr1_photons(s, t, m)
        if snr1 >= sat:
            raise BenchSimError(
                f"stage {m} saturates at {sat:.3g} photons per pixel per frame, before its SNR reaches 1 "
                f"({snr1:.3g}): reproduce's dynamic range has nothing to measure; widen the word or "
                "the full well, or lower the noise"
            )


def _stages(cfg: BenchConfig) -> tuple[list[int], tuple[int, ...]]:
    """The stages of the pass (Fig. 3's within the sensor, and ``mu1``, ``mu2``) and Fig. 3's."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    fig3 = tuple(m for m in FIG3_STAGES if m <= cfg.sensor.rows) or (mu1, mu2)
    return sorted(set(fig3) | {mu1, mu2}), fig3


def _pass_with_progress(
    cfg: BenchConfig, stages: list[int], rng: np.random.Generator, on_first: Callable[[], None] | None = None
) -> PassResult:
    """Render every frame of the pass and stream it through the sensor and DTDI (one simulate
    pass; the truth of stages ``mu1`` and ``mu2``), with a progress bar over the frames;
    ``on_first()`` at its first frames."""
    frames = cfg.lines + max(stages) - 1
    with progress_bar("render + sensor + DTDI", frames, "frames") as bar:
        first = [on_first]

        def advance(n: int) -> None:
            call, first[0] = first[0], None
            if call is not None:
                call()
            bar.advance(n)

        # the truth where the metrics read it: the fusion's two stages (Fig. 3's others need none)
        fusion = (cfg.fusion.mu1, cfg.fusion.mu2)
        return run_pass(cfg, stages, rng, truth=True, truth_stages=fusion, on_frames=advance,
                        variables=PASS_VARIABLES_READ)


@dataclass
class _Beside:
    """The steps queued on the lane beside the pass: the waits for their results."""

    chain: Callable[[], ChainDR]
    stage_mtf: Callable[[], Any]


def _chain_dr(cfg: BenchConfig, rng: np.random.Generator, quick: bool) -> ChainDR:
    """The whole-chain DR measurement (photon-transfer series), drawing from ``rng``."""
    levels: dict[str, Any] = {"n_levels": QUICK_DR_LEVELS} if quick else {}
    return measure_chain_dynamic_range(cfg, rng, columns=min(CHAIN_DR_COLUMNS, cfg.sensor.columns), **levels)


def _pass_and_beside(
    cfg: BenchConfig, stages: list[int], rng: np.random.Generator, seed: int, quick: bool, lane: Lane,
    timer: _Timer,
) -> tuple[PassResult, _Beside]:
    """The pass and, on ``lane`` beside it, the whole-chain DR measurement; then, queued on the
    lane, the companion pass of the sharpness (:func:`measure_stage_mtf`, its own stream).

    The DR measurement draws from ``rng`` where the pass stopped drawing: the pass draws all it
    draws (render seed, fixed pattern, noise seed) before its first frames, so the measurement
    starts then, from a copy of the generator. Should the generator have moved on after that
    (a pass that draws later), the copy is dropped and the measurement runs after the pass from
    ``rng`` itself: the numbers never depend on the overlap. The companion pass starts after the
    pass (beside the pass's metrics and figures): run beside it, the two passes' working sets
    add up in the run's peak memory for no gain in time on two cores."""
    queued: dict[str, Any] = {}

    def chain(gen: np.random.Generator) -> ChainDR:
        with timer.timed("metrics"):
            return _chain_dr(cfg, gen, quick)

    def stage_mtf() -> Any:
        with timer.timed("sharpness"):
            return measure_stage_mtf(cfg, seed, release_render=True)

    def on_first() -> None:
        queued["state"] = rng.bit_generator.state
        queued["chain"] = lane.submit(functools.partial(chain, copy.deepcopy(rng)))
        lane.submit(writing.warm_up)

    sim = _pass_with_progress(cfg, stages, rng, on_first if lane.parallel else None)
    if queued.get("state") != rng.bit_generator.state:
        queued["chain"] = lane.submit(functools.partial(chain, rng))
    return sim, _Beside(queued["chain"], lane.submit(stage_mtf))


def _fuse(cfg: BenchConfig, sim: PassResult) -> tuple[FusionResult, np.ndarray]:
    """Eq. 11 of stages ``mu1``, ``mu2`` (their words' offsets removed:
    :func:`bench_sim.fusion.stage_pair.fuse_stage_words`) and the 8-bit display ``Gamma_TRA``."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    fused = fuse_stage_words(cfg, sim.stage_dn[mu1], sim.stage_dn[mu2])
    tra01 = tone_map(fused.hdr, cfg.fusion.tra, full_scale_dn=fused.full_scale_dn)
    return fused, quantize_display(tra01, 8)


def _shape(cfg: BenchConfig, stages: list[int], fig3: tuple[int, ...]) -> RunShape:
    mu1, mu2, beta = cfg.fusion.mu1, cfg.fusion.mu2, cfg.dtdi.beta_bits
    off = stage_offsets_dn(cfg, (mu1, mu2))
    off1, off2 = off[mu1], off[mu2]
    return RunShape(
        mu1=mu1, mu2=mu2, beta=beta, phi_fs_dn=2**beta, pedestal_dn=cfg.dtdi.pedestal_dn,
        stage_offset_dn={"gamma1": off1, "gamma2": off2}, lines=cfg.lines, columns=cfg.sensor.columns,
        rows=cfg.sensor.rows, frames=cfg.lines + max(stages) - 1, stages=list(stages), fig3_stages=list(fig3),
    )


def _scene(pm: PassMetrics) -> SceneResult:
    if pm.darkest_patch is None or pm.brightest_patch is None or pm.qualitative is None:
        raise BenchSimError(f"reproduce: {pm.no_patches}")  # check_reproducible rules it out
    return SceneResult(pm.saturated_fraction, pm.darkest_patch, pm.brightest_patch, pm.qualitative,
                       clipped_fraction=pm.clipped_fraction)


def _result(
    cfg: BenchConfig, stages: list[int], fig3: tuple[int, ...], sim: PassResult, chain: ChainDR,
    pm: PassMetrics, meta: dict[str, Any],
) -> ReproduceResult:
    """The run's result, less its timings."""
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    info = sim.setup.info
    return ReproduceResult(
        shape=_shape(cfg, stages, fig3),
        dynamic_range=DynamicRangeResult.from_chain(
            chain, dr_increase_eq15_db(mu1, mu2), stage_pairs_for_db(PAPER["delta_psi_db"], FIG3_STAGES)
        ),
        table1=Table1Result.from_pass(pm, sim.stage_dn[mu1].size),
        scene=_scene(pm),
        record=RunRecord(int(meta["seed"]), meta["config_sha256"], meta["version"], info["engine"],
                         info["variant"]),
    )


def run_reproduce(
    cfg: BenchConfig, *, seed: int, out: Path, quick: bool = False, seeds: int = 1
) -> dict[str, Any]:
    """Run the reproduction and write its outputs into ``out``. Returns ``metrics.json``'s dict
    (:meth:`~bench_sim.workflows.reproduce.result.ReproduceResult.to_dict`). ``seeds > 1``: the
    headline numbers also over seeds ``seed .. seed + seeds - 1`` as mean +- sd (the files are
    seed ``seed``'s)."""
    seed = check_seed(seed)
    if quick:
        cfg = quick_config(cfg)
    stages, fig3 = _stages(cfg)
    seeds = check_seeds(seed, seeds, cfg, stages)
    check_reproducible(cfg)
    out = preflight(cfg, out=out, estimate=estimate_reproduce(cfg, stages))
    t_start = time.perf_counter()
    timer = _Timer(TIMED_STEPS)
    rng = np.random.default_rng(seed)
    with Lane() as lane:
        # 1-2. render + sensor + DTDI (one simulate pass); beside it the whole-chain DR (the
        # generator goes on there) and the sharpness per stage (a companion pass with slanted edges)
        sim, beside = _pass_and_beside(cfg, stages, rng, seed, quick, lane, timer)
        for step in ("render_setup", "render_frames", "sensor_dtdi", "pass_wall"):
            timer.add(step, sim.timings_s[step])
        # what the pass held to render (its engine, records, texture blocks) and the free memory
        # its working set left in the allocator: given back before the outputs' working sets
        release(sim.setup)
        give_back()
        # 3. fusion and display transform
        with timer.timed("fusion"):
            fused, tra8 = _fuse(cfg, sim)
        setup = sim.setup
        meta = provenance(cfg, seed, quick=quick, render=render_provenance(setup.info),
                          backend=setup.backend.as_dict())
        record = {"command": "reproduce", "quick": quick, "version": meta["version"], "seed": int(seed),
                  "config_sha256": meta["config_sha256"]}
        with output_set(out, record) as tmp:  # the files as one set: all of them or none
            try:
                with large_blocks_mapped():  # the outputs' temporaries leave no holes behind
                    result = _outputs(tmp, cfg, (stages, fig3), sim, fused, tra8, beside, lane, meta, timer)
            except BaseException:
                lane.cancel()  # no step of the lane goes on writing into the folder removed now
                raise
            if seeds > 1:
                result = replace(result, seeds=_over_seeds(cfg, stages, fig3, seed, seeds, quick, result))
            # like the timings, a fact of this process (fewer renders when it had the records cached)
            result = replace(result, timings=RunTimings(
                {k: round(v, 3) for k, v in timer.steps.items()}, round(time.perf_counter() - t_start, 3),
                int(setup.info["mitsuba_renders"]),
            ))
            metrics = result.to_dict()
            write_json(tmp / "metrics.json", metrics)
            write_report(tmp / "report.md", result, cfg, quick)
    _print_timings(result.timings, out)
    return metrics


def _outputs(
    tmp: Path, cfg: BenchConfig, stage_sets: tuple[list[int], tuple[int, ...]], sim: PassResult,
    fused: FusionResult, tra8: np.ndarray, beside: _Beside, lane: Lane, meta: dict[str, Any], timer: _Timer,
) -> ReproduceResult:
    """The metrics of the pass and the files into ``tmp``: the image files on the pool; the SNR
    and sharpness figures (after the lane's measurements) and Fig. 3 on ``lane`` while the pass's
    metrics are computed here, then Fig. 4 and the truth figures. Returns the result (less
    timings and seeds)."""
    stages, fig3 = stage_sets
    t0 = time.perf_counter()
    files_written = start_image_files(tmp, cfg, meta, sim.stage_dn, fused, tra8)
    lane.submit(lambda: snr_figure(tmp / "snr_vs_signal.png", beside.chain(), meta))
    lane.submit(lambda: _stage_mtf_files(beside, cfg, tmp, meta))
    lane.submit(lambda: writing.fig3(tmp / "fig3_stages.png", sim.stage_dn, fig3, cfg.dtdi.beta_bits, meta))
    with timer.timed("metrics"):
        pm = pass_metrics(cfg, sim, fused)
        scores = fusion_scores(cfg, sim, fused)  # Gamma_HDR against its exact truth, eq. 11 and clip-aware
    sim.drop(*PASS_VARIABLES_READ)  # the truth, read: not held while the figures are drawn
    writing.fig4(tmp / "fig4_hdr.png", cfg, _inset_boxes(sim.setup.grid.panel, cfg, cfg.lines), meta,
                 sim.stage_dn, fused, tra8, sim.setup.grid.panel, sim.setup.geom)
    give_back()  # the metrics' and Fig. 4's free memory, before the largest figures' working sets
    writing.drawn(lambda: write_truth_figures(scores, tmp, meta))
    result = _result(cfg, stages, fig3, sim, beside.chain(), pm, meta)
    result = replace(result, truth=TruthResult(scores.summary))
    write_table1(tmp / "table1.csv", result)
    files_written()
    lane.join()
    result = replace(result, sharpness=sharpness_result(beside.stage_mtf(), cfg))
    timer.add("write", time.perf_counter() - t0)
    return result


def _stage_mtf_files(beside: _Beside, cfg: BenchConfig, folder: Path, meta: dict[str, Any]) -> None:
    """``mtf50_vs_stage.csv`` and ``.png`` of the companion pass (:func:`write_stage_mtf`)."""
    ds = beside.stage_mtf()
    writing.drawn(lambda: write_stage_mtf(ds, cfg, folder, meta))


def _over_seeds(
    cfg: BenchConfig, stages: list[int], fig3: tuple[int, ...], seed: int, n: int, quick: bool,
    first: ReproduceResult,
) -> SeedsResult:
    """The headline numbers over seeds ``seed .. seed + n - 1`` (``first`` is seed ``seed``'s
    run): each further seed runs the pass, the fusion, the chain DR and the metrics (no files)."""
    runs = [headline_numbers(first.to_dict())]
    levels: dict[str, Any] = {"n_levels": QUICK_DR_LEVELS} if quick else {}
    for s in range(seed + 1, seed + n):
        rng = np.random.default_rng(s)
        sim = _pass_with_progress(cfg, stages, rng)
        fused, _ = _fuse(cfg, sim)
        columns = min(CHAIN_DR_COLUMNS, cfg.sensor.columns)
        chain = measure_chain_dynamic_range(cfg, rng, columns=columns, **levels)
        pm = pass_metrics(cfg, sim, fused)
        meta = provenance(cfg, s, quick=quick, render=render_provenance(sim.setup.info),
                          backend=sim.setup.backend.as_dict())
        res = replace(_result(cfg, stages, fig3, sim, chain, pm, meta),
                      truth=TruthResult(fusion_scores(cfg, sim, fused).summary))
        runs.append(headline_numbers(res.to_dict()))
    return SeedsResult(list(range(seed, seed + n)), seed_spread(runs))


def _print_timings(timings: RunTimings | None, out: Path) -> None:
    if timings is None:
        return
    for step, s in timings.timings_s.items():
        print(f"  {step:<12} {s:8.2f} s")
    print(f"  {'total':<12} {timings.wall_s:8.2f} s  -> {out}")
