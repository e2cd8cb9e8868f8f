"""One pass: frames -> sensor -> DTDI -> stage images and their truth (:func:`run_pass`; the
package docstring of :mod:`bench_sim.pipeline` describes it)."""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.pipeline.fused_images import fused_images
from bench_sim.pipeline.store_schema import COORD_ATTRS, pass_attrs, pass_coords
from bench_sim.pipeline.variables import (
    PASS_VARIABLES,
    check_variables,
    pass_dtypes,
    pedestal_dn,
    variable_attrs,
)
from bench_sim.render.exposures import RenderSetup, iter_radiance_frames, photons_of, prepare
from bench_sim.render.frame_kernel import TAP_LOOP
from bench_sim.runtime.jit import Loop, warm_up
from bench_sim.runtime.parallel import prefetch, seed_sequence
from bench_sim.sensor import cumulant_kernel, diagonal_sums, exposure_kernel
from bench_sim.sensor.dtdi import check_stage_subset, check_stages, frames_needed, full_scale_dn
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern
from bench_sim.sensor.pass_lines import ArraySink, LineAssembler, PassSink
from bench_sim.sensor.pass_truth import PassTruth
from bench_sim.sensor.stream import DEFAULT_CHUNK_FRAMES, iter_stream

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "run_pass", "PassResult", "Read", "SENSOR_CHUNK_FRAMES", "RENDER_CHUNK_FRAMES", "TRUTH_BAND_LINES",
    "pass_loops",
]

#: Frames exposed per vectorised sensor call (the temporal noise depends on it: fixed).
SENSOR_CHUNK_FRAMES = DEFAULT_CHUNK_FRAMES
#: Frames rendered per engine call (a multiple of the sensor chunk).
RENDER_CHUNK_FRAMES = 64
#: Output lines per band of the reflectance truth (the lines a streamed pass holds besides the
#: ``max(stages)`` in progress; the values do not depend on it).
TRUTH_BAND_LINES = 64


#: ``read(name, stage)``: a pass's variable ``name`` of stage ``stage`` (``None``: an image variable)
Read = Callable[[str, "int | None"], np.ndarray]


@dataclass
class PassResult:
    """What :func:`run_pass` returns.

    Attributes
    ----------
    dataset
        The simulation (see the module docstring); without ``mean_dn``, ``photons``,
        ``reflectance`` and ``clipped`` when run with ``truth=False``. Built when first read
        (a caller that only needs ``stage_dn`` does not import xarray). Its arrays, stages and
        attributes are also here without it: :meth:`read`, :meth:`values`, ``stages``,
        ``variables``, ``attrs`` (what a worker reads without importing xarray).
    stage_dn
        Stage ``m`` -> (lines, N) stage words, ``uint16`` for ``beta <= 16`` (the default 12),
        else ``uint32`` (:func:`bench_sim.sensor.model.word_dtype`; the arrays behind
        ``dataset.dn``).
    setup
        The render set-up (geometry, target grid and panel, engine info, backend).
    truth
        Whether the pass computed the truth (``dataset`` then has ``mean_dn``, ``photons``,
        ``reflectance``, ``clipped``); reading it does not build the dataset.
    timings_s
        Seconds per step: ``render_setup``; ``render_frames``, ``sensor_dtdi``, ``truth``
        (busy time of each; rendering runs ahead in its own thread and the chunks are exposed
        on the thread pool, so they overlap); ``pass_wall``, the wall time of the streaming
        pass they share.
    stages
        The stages of ``dataset`` (its ``stage`` coordinate): the pass's, or those of its truth
        when run with ``truth_stages``.
    """

    stage_dn: dict[int, np.ndarray]
    setup: RenderSetup
    timings_s: dict[str, float] = field(default_factory=dict)
    truth: bool = False
    #: the arrays behind ``dataset`` (:class:`~bench_sim.sensor.pass_lines.ArraySink`), ``None`` with a sink
    arrays: ArraySink | None = field(default=None, repr=False)
    stages: tuple[int, ...] = ()
    #: the dataset's attributes when first read (:func:`~bench_sim.pipeline.store_schema.pass_attrs`)
    make_attrs: Callable[[], dict[str, Any]] | None = field(default=None, repr=False)
    #: the dataset of ``variables`` and ``attrs`` (:func:`_make_dataset`)
    make_dataset: Callable[[PassResult], xr.Dataset] | None = field(default=None, repr=False)

    def stage_array(self, name: str, stage: int) -> np.ndarray:
        """Stage variable ``name`` of stage ``stage``: the array behind
        ``dataset[name].sel(stage=stage)``, read without building the dataset (xarray)."""
        if self.arrays is None or name not in self.arrays.index or stage not in self.arrays.index[name]:
            raise BenchSimError(f"PassResult: no {name} of stage {stage}")
        return self.arrays.arrays[name][self.arrays.index[name][stage]]

    def read(self, name: str, stage: int | None) -> np.ndarray:
        """A :data:`Read` of the pass: stage variable ``name`` of ``stage`` (:meth:`stage_array`),
        or the image variable ``name`` (``stage`` ``None``): the array behind
        ``dataset[name].sel(stage=stage)`` / ``dataset[name]``, without xarray."""
        if stage is not None:
            return self.stage_array(name, stage)
        if self.arrays is None or name in self.arrays.index or name not in self.arrays.arrays:
            raise BenchSimError(f"PassResult: no image variable {name}")
        return self.arrays.arrays[name]

    def values(self, name: str) -> np.ndarray:
        """The array behind ``dataset[name].values``: (stage, line, column) at :attr:`stages` for
        a stage variable (``dn`` at the stages of the truth only when it has fewer), (line,
        column) for an image variable."""
        if self.arrays is None or name not in self.arrays.arrays:
            raise BenchSimError(f"PassResult: no {name}")
        arr = self.arrays.arrays[name]
        held = tuple(self.arrays.index.get(name, {}))
        if name not in self.arrays.index or held == self.stages:
            return arr
        return arr[[self.arrays.index[name][m] for m in self.stages]]

    @property
    def variables(self) -> set[str]:
        """The names of the pass's variables held (``dataset``'s data variables)."""
        return set() if self.arrays is None else set(self.arrays.arrays)

    def drop(self, *names: str) -> None:
        """Let go of the arrays of the stage variables ``names`` (a caller done with them, e.g.
        with the truth once scored): :meth:`stage_array` no longer has them, and a ``dataset``
        not built yet is built without them. ``dn`` (``stage_dn``) stays."""
        if self.arrays is not None:
            for name in set(names) - {"dn"}:
                self.arrays.arrays.pop(name, None)
                self.arrays.index.pop(name, None)

    @functools.cached_property
    def attrs(self) -> dict[str, Any]:
        """The attributes of ``dataset`` (:func:`~bench_sim.pipeline.store_schema.pass_attrs`:
        config, seed, version, engine, ``t_int_s``, the sensor's constants, ...), without xarray."""
        if self.make_attrs is None:
            raise BenchSimError("PassResult: no attributes")
        return self.make_attrs()

    @functools.cached_property
    def dataset(self) -> xr.Dataset:
        if self.make_dataset is None:
            raise BenchSimError("PassResult: no dataset")
        return self.make_dataset(self)


# --- the steps of a pass -------------------------------------------------------------------------


def _rendered(setup: RenderSetup, n_rows: int, timings: dict[str, float]) -> Iterator[np.ndarray]:
    """The pass's photon frames (rows ``0 .. n_rows - 1``) in pieces of :data:`SENSOR_CHUNK_FRAMES`:
    chunks of :data:`RENDER_CHUNK_FRAMES` frames rendered a chunk ahead in their own thread
    (:func:`bench_sim.runtime.parallel.prefetch`), handed over as their float32 radiance (half the
    bytes of their photons in flight) and turned into photons a piece at a time (the same values)."""

    def rendered() -> Iterator[np.ndarray]:
        frames_iter = iter_radiance_frames(setup, chunk=RENDER_CHUNK_FRAMES)
        while True:
            t0 = time.perf_counter()
            chunk = next(frames_iter, None)
            timings["render_frames"] += time.perf_counter() - t0
            if chunk is None:
                return
            yield chunk

    for chunk in prefetch(rendered()):
        for k in range(0, chunk.shape[0], SENSOR_CHUNK_FRAMES):
            t0 = time.perf_counter()
            piece = photons_of(setup, chunk[k : k + SENSOR_CHUNK_FRAMES, :n_rows])
            timings["render_frames"] += time.perf_counter() - t0
            yield piece
        del chunk  # not held while the next is awaited


def _stream(
    cfg: BenchConfig,
    setup: RenderSetup,
    fp: FixedPattern,
    noise: np.random.SeedSequence,
    st: tuple[int, ...],
    lines_out: LineAssembler,
    truth: PassTruth | None,
    timings: dict[str, float],
    on_frames: Callable[[int], None] | None,
) -> None:
    """The streaming pass: rendered frames through the sensor and DTDI, the words of every
    completed line and, with ``truth``, their truth into ``lines_out``."""
    lines = cfg.lines
    done = dict.fromkeys(st, 0)
    t_pass = time.perf_counter()
    chunks = iter_stream(
        _rendered(setup, st[-1], timings), cfg.sensor, cfg.dtdi, setup.geom.t_int_s, st, fp, noise,
        pedestal_dn=pedestal_dn(cfg), chunk_frames=SENSOR_CHUNK_FRAMES, saturated=truth is not None,
    )
    for got in chunks:
        t0 = time.perf_counter()
        for m, block in got.lines.items():
            take = block[: max(lines - done[m], 0)]
            lines_out.put("dn", m, done[m], take)
            done[m] += len(take)
        t1 = time.perf_counter()
        timings["sensor_dtdi"] += got.seconds + t1 - t0
        if truth is not None:
            for tb in truth.push(got.exposed):
                lines_out.put(tb.name, tb.stage, tb.line0, tb.values)
            timings["truth"] += time.perf_counter() - t1
        if on_frames is not None:
            on_frames(got.exposed.photons.shape[0])
    timings["pass_wall"] = time.perf_counter() - t_pass
    if min(done.values()) < lines:
        raise BenchSimError(f"simulate: the pass gave only {min(done.values())} of {lines} lines")


def _make_dataset(cfg: BenchConfig, sim: PassResult) -> xr.Dataset:
    """The pass's :class:`xarray.Dataset` (see the module docstring) of its arrays
    (:meth:`PassResult.values`, at its ``stages``) and attributes (:attr:`PassResult.attrs`)."""
    import xarray as xr

    data: dict[str, Any] = {
        v.name: (v.dims, sim.values(v.name)) for v in PASS_VARIABLES if v.name in sim.variables
    }
    ds = xr.Dataset(data, coords=pass_coords(cfg, sim.stages))
    for name, var in ds.data_vars.items():
        var.attrs.update(variable_attrs(cfg, str(name)))
    for name, attrs in COORD_ATTRS.items():
        ds[name].attrs.update(attrs)
    ds.attrs.update(sim.attrs)
    return ds


def run_pass(
    cfg: BenchConfig,
    stages: Iterable[int],
    seed: int | np.random.SeedSequence | np.random.Generator,
    *,
    truth: bool = True,
    on_frames: Callable[[int], None] | None = None,
    fixed_pattern: FixedPattern | None = None,
    sink: Callable[[RenderSetup], PassSink] | None = None,
    truth_stages: Iterable[int] | None = None,
    variables: Iterable[str] | None = None,
) -> PassResult:
    """Run one simulation pass: render, expose, accumulate stages and truth, fuse.

    The building block of :func:`bench_sim.workflows.simulate.simulate`, ``reproduce``, sweeps
    and data sets.

    Parameters
    ----------
    cfg
        The bench; ``cfg.lines`` output lines of ``cfg.sensor.columns`` columns.
    stages
        Stages to output, each in ``1 .. sensor.rows``
        (:func:`bench_sim.sensor.dtdi.check_stages`).
    seed
        Root seed, a ``SeedSequence`` (a sample's or sweep point's stream) or a generator to
        draw from, consumed in this order: one integer for the renderer (reference engine),
        the sensor's fixed pattern, then one ``SeedSequence`` of the temporal noise, from which
        chunk ``c`` of :data:`SENSOR_CHUNK_FRAMES` frames (rows ``0 .. max(stages) - 1``) gets
        its own generator (:func:`bench_sim.runtime.parallel.chunk_generator`): the result does not
        depend on the number of threads (``BENCH_SIM_THREADS``).
    truth
        Also compute ``mean_dn``, ``photons``, ``reflectance`` and ``clipped``.
    on_frames
        Called with the number of frames after every rendered chunk (progress bars).
    fixed_pattern
        Use this physical sensor (its fixed patterns, shape ``(sensor.rows, sensor.columns)``)
        instead of the one drawn from ``seed`` (which is still drawn, so the temporal noise is
        the same): one camera for many passes (a dataset's ``camera = "fixed"``).
    sink
        Stream the pass instead of keeping it: called with the render set-up once it is made,
        returns the :class:`~bench_sim.sensor.pass_lines.PassSink` that receives every variable's
        completed lines (stage words, truth, fused image; as the dataset would hold them) while
        the pass runs. The result then has no arrays (``stage_dn`` empty, no ``dataset``).
    truth_stages
        With ``truth``: compute it for these of the ``stages`` only (default: all of them),
        reading only their rows (the truth of a stage does not depend on the others). The
        ``dataset`` then holds these stages (``stage_dn`` has every stage's words); the maps of
        ``gamma_hdr`` need both fusion stages among them. Not with ``sink``.
    variables
        Keep only these of :data:`~bench_sim.pipeline.variables.PASS_VARIABLES` (``dn`` always;
        default all): the truth computes only what they are made of, the image variables not
        named are not made; the values kept are the same bytes. Not with ``sink``.
    """
    st = check_stages(stages, cfg.sensor.rows)
    sensor_chain(cfg.sensor)  # the chain's effects checked before anything is rendered
    some = st if truth_stages is None else check_stage_subset(truth_stages, st, "truth_stages")
    tst = some if truth else None
    keep = None if variables is None else check_variables(tuple(variables))
    if sink is not None and (tst not in (None, st) or keep is not None):
        what = "truth_stages" if tst not in (None, st) else "variables"
        raise BenchSimError(f"run_pass: {what} is not supported with a sink (it writes all of a pass)")
    rng = np.random.default_rng(seed)  # a Generator is used as is
    n_rows, n_cols = st[-1], cfg.sensor.columns
    timings = {"render_setup": 0.0, "render_frames": 0.0, "sensor_dtdi": 0.0, "truth": 0.0, "pass_wall": 0.0}
    t0 = time.perf_counter()
    warm_up(pass_loops(cfg, truth=tst is not None))  # loaded beside the set-up
    setup = prepare(cfg, frames_needed(cfg.lines, st), rng)
    timings["render_setup"] = time.perf_counter() - t0
    fixed = _fixed_pattern(cfg, rng, fixed_pattern)
    noise = seed_sequence(rng)
    fp = fixed if n_rows == cfg.sensor.rows else fixed.window(n_rows, n_cols)
    lines_out, array_sink = _assembler(cfg, (st, tst), truth, sink, setup, keep)
    stage_truth = None if tst is None else _pass_truth(cfg, setup, fp, tst, n_rows, timings, keep)
    _stream(cfg, setup, fp, noise, st, lines_out, stage_truth, timings, on_frames)
    if array_sink is None:
        return PassResult({}, setup, timings, truth=truth)
    return _result(cfg, seed, setup, timings, (st, tst), array_sink)


def _result(
    cfg: BenchConfig, seed: int | np.random.SeedSequence | np.random.Generator, setup: RenderSetup,
    timings: dict[str, float], stage_sets: tuple[tuple[int, ...], tuple[int, ...] | None], arrays: ArraySink,
) -> PassResult:
    """The :class:`PassResult` of a pass kept in ``arrays`` (stages ``st``, truth of stages ``tst``:
    ``stage_sets``): its dataset at the stages of its truth, its attributes made when first read."""
    st, tst = stage_sets
    dn = {m: arrays.arrays["dn"][s] for s, m in enumerate(st)}
    attrs = functools.partial(pass_attrs, cfg, seed, setup, fused="gamma_hdr" in arrays.arrays)
    return PassResult(dn, setup, timings, truth=tst is not None, arrays=arrays,
                      stages=st if tst is None else tst, make_attrs=attrs,
                      make_dataset=functools.partial(_make_dataset, cfg))


def _pass_truth(
    cfg: BenchConfig, setup: RenderSetup, fp: FixedPattern, tst: tuple[int, ...], n_rows: int,
    timings: dict[str, float], keep: tuple[str, ...] | None,
) -> PassTruth:
    """The truth of stages ``tst`` of the pass, its variables among ``keep`` (default all; its
    set-up timed as the truth's)."""
    t0 = time.perf_counter()
    out = PassTruth(cfg, setup, fp, tst, pedestal_dn=pedestal_dn(cfg), band_lines=TRUTH_BAND_LINES,
                    footprint_rows=n_rows, variables=keep)
    timings["truth"] += time.perf_counter() - t0
    return out


def pass_loops(cfg: BenchConfig, *, truth: bool) -> tuple[Loop, ...]:
    """The compiled loops (:mod:`bench_sim.runtime.jit`) a pass of ``cfg`` runs."""
    frames = (TAP_LOOP,) if cfg.render.engine == "fast" else ()
    return frames + exposure_kernel.LOOPS + diagonal_sums.LOOPS + (cumulant_kernel.LOOPS if truth else ())


def _fixed_pattern(cfg: BenchConfig, rng: np.random.Generator, given: FixedPattern | None) -> FixedPattern:
    """The pass's physical sensor: drawn from ``rng`` (always, so the noise after it is the same),
    or ``given``."""
    fixed = draw_fixed_pattern(cfg.sensor, rng)
    if given is not None and given.shape != fixed.shape:
        raise BenchSimError(f"fixed_pattern: shape {given.shape}, the sensor is {fixed.shape} "
                            "(rows, columns)")
    return fixed if given is None else given


def _assembler(
    cfg: BenchConfig, stage_sets: tuple[tuple[int, ...], tuple[int, ...] | None], truth: bool,
    sink: Callable[[RenderSetup], PassSink] | None, setup: RenderSetup, keep: tuple[str, ...] | None,
) -> tuple[LineAssembler, ArraySink | None]:
    """The pass's line assembler (stages ``st``, truth of stages ``tst``: ``stage_sets``; the
    variables ``keep``, default all) and, without ``sink``, its arrays."""
    st, tst = stage_sets
    stage_dtypes, image_dtypes = pass_dtypes(cfg, st, truth=truth, truth_stages=tst, variables=keep)
    stages_of = {n: tst for n in stage_dtypes if n != "dn"} if tst is not None else None
    arrays = None if sink is not None else ArraySink(
        st, cfg.lines, cfg.sensor.columns, stage_dtypes, image_dtypes, stages_of
    )
    out = arrays if arrays is not None else sink(setup)  # type: ignore[misc]
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    fuse = (mu1, mu2, lambda g1, g2: _kept(fused_images(cfg, g1, g2), image_dtypes)) if image_dtypes else None
    top = float(full_scale_dn(cfg.dtdi.beta_bits) - 1)
    return LineAssembler(st, stage_dtypes, out, top, fuse, stages_of), arrays


def _kept(images: dict[str, np.ndarray], names: Iterable[str]) -> dict[str, np.ndarray]:
    """The image variables of ``images`` among ``names``."""
    return {n: images[n] for n in names}
