"""Sensor + DTDI in one streaming pass: photons per pixel per frame -> stage images.

:func:`iter_stream` is the one sensor + DTDI loop of the package: frames of mean photons (from
the renderer in :func:`bench_sim.pipeline.run_pass`, or a uniform field for the photon-transfer
measurement, :func:`bench_sim.measure.uniform_field.expose_uniform`) go through the EMVA 1288
pixel model (:func:`bench_sim.sensor.emva.expose`) in chunks of frames and straight into the
streaming :class:`bench_sim.sensor.dtdi.DTDIAccumulator`; only the output stage images grow with
the number of lines.

Chunks of :data:`DEFAULT_CHUNK_FRAMES` frames are exposed on the thread pool
(:mod:`bench_sim.runtime.parallel`, ``BENCH_SIM_THREADS``), chunk ``c`` with its own generator
``chunk_generator(noise, c)`` spawned from one ``SeedSequence`` (``noise``) drawn from the run's
generator, and accumulated in frame order: the stage images are the same for any number of
threads.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.runtime.parallel import chunk_generator, ordered_imap, seed_sequence
from bench_sim.sensor.dtdi import DTDIAccumulator, collect_stage_lines, validate_stages
from bench_sim.sensor.emva import ExposurePlan, FixedPattern, draw_fixed_pattern, expose

__all__ = [
    "sensor_dtdi_pass",
    "iter_sensor_dtdi",
    "iter_stream",
    "StreamedChunk",
    "iter_exposed",
    "Exposed",
    "DEFAULT_CHUNK_FRAMES",
]

#: Frames exposed per vectorised call, each chunk with its own random stream. The temporal noise
#: drawn depends on this chunking (the frames are re-chunked to it whatever the input's own
#: chunking), so keep it fixed for reproducible runs.
DEFAULT_CHUNK_FRAMES = 16


def _as_float(arr: np.ndarray) -> np.ndarray:
    return arr if arr.dtype in (np.float32, np.float64) else arr.astype(np.float64)


def _rechunk(frames: np.ndarray | Iterable[np.ndarray], size: int) -> Iterator[np.ndarray]:
    """Yield (C, M, N) float chunks of exactly ``size`` frames (the last may be shorter)."""
    if isinstance(frames, np.ndarray):
        if frames.ndim != 3:
            raise BenchSimError(f"photons shape {frames.shape}: expected (frames, rows, columns)")
        for start in range(0, frames.shape[0], size):
            yield _as_float(np.asarray(frames[start : start + size]))
        return
    buf: list[np.ndarray] = []
    n = 0
    for item in frames:
        arr = _as_float(np.asarray(item))
        if arr.ndim == 2:
            arr = arr[None]
        if arr.ndim != 3:
            raise BenchSimError(f"photon frame shape {arr.shape}: expected (rows, columns)")
        buf.append(arr)
        n += arr.shape[0]
        while n >= size:
            joined = np.concatenate(buf) if len(buf) > 1 else buf[0]
            yield joined[:size]
            rest = joined[size:]
            buf = [rest] if len(rest) else []
            n = len(rest)
    if n:
        yield np.concatenate(buf) if len(buf) > 1 else buf[0]


@dataclass(frozen=True)
class Exposed:
    """One exposed chunk: its photons, raw pixel values [DN], the saturated reads (or None)
    and the seconds its exposure took (in its pool thread)."""

    photons: np.ndarray
    dn: np.ndarray
    saturated: np.ndarray | None
    seconds: float


def iter_exposed(
    chunks: Iterable[np.ndarray],
    sensor: SensorConfig,
    fixed: FixedPattern,
    t_int_s: float,
    noise: np.random.SeedSequence,
    *,
    saturated: bool = False,
) -> Iterator[Exposed]:
    """Expose chunks of frames on the thread pool (:func:`bench_sim.runtime.parallel.ordered_imap`),
    chunk ``c`` drawing from :func:`bench_sim.runtime.parallel.chunk_generator` ``(noise, c)``; yields
    them in order, a few chunks exposed ahead of the consumer. ``saturated``: also return the
    saturated reads (see :func:`bench_sim.sensor.emva.expose`)."""

    plan = ExposurePlan.of(sensor, fixed, t_int_s)  # once for every chunk

    def one(item: tuple[int, np.ndarray]) -> Exposed:
        c, ph = item
        t0 = time.perf_counter()
        sat = np.empty(ph.shape, dtype=bool) if saturated else None
        raw = expose(ph, sensor, fixed, t_int_s, chunk_generator(noise, c), saturated=sat, plan=plan)
        return Exposed(ph, raw, sat, time.perf_counter() - t0)

    return ordered_imap(one, enumerate(chunks))


@dataclass(frozen=True)
class StreamedChunk:
    """One chunk of a streaming pass: the exposed chunk (:class:`Exposed`), the stage lines it
    completed (stage ``m`` -> (n, C) block continuing the previous one; n may be 0) and the
    seconds its exposure and accumulation took."""

    exposed: Exposed
    lines: dict[int, np.ndarray]
    seconds: float


def iter_stream(
    photons: np.ndarray | Iterable[np.ndarray],
    sensor: SensorConfig,
    dtdi: DTDIConfig,
    t_int_s: float,
    stages: Sequence[int],
    fixed: FixedPattern,
    noise: np.random.SeedSequence,
    *,
    pedestal_dn: float | Mapping[int, float] | None = None,
    chunk_frames: int = DEFAULT_CHUNK_FRAMES,
    saturated: bool = False,
) -> Iterator[StreamedChunk]:
    """The one sensor + DTDI loop: re-chunk the frames to ``chunk_frames``, expose every chunk
    (:func:`iter_exposed`, chunk ``c`` drawing from ``chunk_generator(noise, c)``) and push its
    raw values through one :class:`~bench_sim.sensor.dtdi.DTDIAccumulator`.

    ``fixed`` is the whole sensor's pattern or exactly the frames' ``R x C``; ``saturated``:
    also return each chunk's saturated reads. The other arguments as in
    :func:`sensor_dtdi_pass`. Nothing is drawn here but the chunks' temporal noise.
    """
    if chunk_frames < 1:
        raise BenchSimError(f"chunk_frames = {chunk_frames!r}: must be >= 1")
    st = validate_stages(stages)
    chunks = _rechunk(photons, chunk_frames)
    first = next(chunks, None)
    if first is None:
        raise BenchSimError("photons: the pass has no frames")
    rows, cols = first.shape[1:]
    if rows > fixed.shape[0] or cols > fixed.shape[1]:
        raise BenchSimError(
            f"photon frames of {rows} x {cols} pixels exceed the sensor's "
            f"{fixed.shape[0]} x {fixed.shape[1]}"
        )
    validate_stages(st, rows)
    fp = fixed if (rows, cols) == fixed.shape else fixed.window(rows, cols)
    acc = DTDIAccumulator(
        cols, st, dtdi.beta_bits, sensor.black_offset_dn, dtdi.subtract_black,
        pedestal_dn=dtdi.pedestal_dn if pedestal_dn is None else pedestal_dn,
    )
    exposed = iter_exposed(itertools.chain([first], chunks), sensor, fp, t_int_s, noise, saturated=saturated)
    for got in exposed:
        t0 = time.perf_counter()
        lines = acc.push_many(got.dn)
        yield StreamedChunk(got, lines, got.seconds + time.perf_counter() - t0)


def iter_sensor_dtdi(
    photons: np.ndarray | Iterable[np.ndarray],
    sensor: SensorConfig,
    dtdi: DTDIConfig,
    t_int_s: float,
    stages: Sequence[int],
    rng: np.random.Generator | np.random.SeedSequence | int,
    *,
    fixed: FixedPattern | None = None,
    pedestal_dn: float | Mapping[int, float] | None = None,
    chunk_frames: int = DEFAULT_CHUNK_FRAMES,
) -> Iterator[dict[int, np.ndarray]]:
    """Stream a pass: expose each chunk of frames and yield the stage lines it completed.

    Memory stays ``O(chunk_frames * R * C)`` for the frames plus the accumulator's ring,
    whatever the number of lines, as long as the caller does not keep the yielded lines.
    Arguments as in :func:`sensor_dtdi_pass`; the loop is :func:`iter_stream`.

    Yields
    ------
    dict
        Per chunk: stage ``m`` -> (n, C) ``uint32`` block of its next complete lines (in line
        order, continuing from the previous block; n may be 0).
    """
    if chunk_frames < 1:
        raise BenchSimError(f"chunk_frames = {chunk_frames!r}: must be >= 1")
    st = validate_stages(stages)
    gen = np.random.default_rng(rng)
    if fixed is None:
        fixed = draw_fixed_pattern(sensor, gen)
    noise = seed_sequence(gen)
    for chunk in iter_stream(
        photons, sensor, dtdi, t_int_s, st, fixed, noise, pedestal_dn=pedestal_dn, chunk_frames=chunk_frames
    ):
        yield chunk.lines


def sensor_dtdi_pass(
    photons: np.ndarray | Iterable[np.ndarray],
    sensor: SensorConfig,
    dtdi: DTDIConfig,
    t_int_s: float,
    stages: Sequence[int],
    rng: np.random.Generator | np.random.SeedSequence | int,
    *,
    fixed: FixedPattern | None = None,
    lines: int | None = None,
    pedestal_dn: float | Mapping[int, float] | None = None,
    chunk_frames: int = DEFAULT_CHUNK_FRAMES,
) -> dict[int, np.ndarray]:
    """Expose frames of photons and accumulate every requested DTDI stage in one pass.

    Parameters
    ----------
    photons
        Mean photons per pixel per frame: a (K, R, C) array or an iterable of (R, C) frames
        and/or (c, R, C) chunks in frame order. ``R <= sensor.rows`` and ``C <= sensor.columns``:
        the frames cover the top-left ``R x C`` pixels of the sensor (a region of interest;
        rows beyond ``max(stages)`` add nothing to any stage).
    sensor, dtdi
        Pixel model and DTDI settings (``beta_bits``, ``subtract_black``).
    t_int_s
        Integration time of one frame [s].
    stages
        Requested stages, each in ``1 .. R``.
    rng
        The run's random generator (or a seed for one). If ``fixed`` is None the fixed pattern
        is drawn from it first (:func:`draw_fixed_pattern` for the whole sensor); then one
        ``SeedSequence`` of the temporal noise (:func:`bench_sim.runtime.parallel.seed_sequence`), from
        which chunk ``c`` of ``chunk_frames`` frames gets its own generator.
    fixed
        The sensor's fixed pattern (whole sensor or exactly ``R x C``).
    lines
        ``None``: each stage gets all its complete lines (``K - m + 1``); ``L``: lines
        ``0 .. L-1`` for every stage (needs ``K >= L + max(stages) - 1`` frames).
    pedestal_dn
        Constant added to every stage value [DN], one value or stage -> value (see
        :mod:`bench_sim.sensor.dtdi`); default (``None``): the config's ``dtdi.pedestal_dn``.
    chunk_frames
        Frames per vectorised :func:`expose` call. The temporal noise drawn depends on it
        (frames are re-chunked to it whatever the input's chunking): keep it fixed.

    Returns
    -------
    dict
        Stage ``m`` -> (lines, C) ``uint32`` stage image (paper eq. 1-2, 4).
    """
    st = validate_stages(stages)
    passes = iter_sensor_dtdi(
        photons, sensor, dtdi, t_int_s, st, rng, fixed=fixed, pedestal_dn=pedestal_dn,
        chunk_frames=chunk_frames,
    )
    return collect_stage_lines(passes, st, lines)
