"""Digital time-delay integration (DTDI): raw pixel frames -> stage images, all stages in one pass.

Indexing (0-based, as in the code): frames ``k = 0 .. K-1``, sensor rows ``i = 0 .. M-1``.
Row ``i`` in frame ``k`` sees scene line ``j = k - i`` (the image moves one row per line period).
The stage-``m`` value of line ``j`` sums the ``m`` rows that saw it (paper eq. 1-2, with the
paper's 1-based ``i`` shifted to 0-based)::

    gamma_m[j, n] = sum_{i = 0 .. m-1} v[frame j + i, row i, column n]

Which lines come out
--------------------
Stage ``m`` of line ``j`` is complete after frame ``j + m - 1``. A pass of ``K`` frames
therefore yields the *complete* lines ``j = 0 .. K - m`` (``K - m + 1`` lines) of stage ``m``:

* lines ``j < 0`` (scene lines that were already under rows ``i > 0`` when the pass started)
  never get their first rows and are dropped;
* lines ``j > K - m`` (still under the sensor when the pass ends) are partial and dropped.

No partial sum is ever output. To get the same ``L`` lines ``0 .. L-1`` for every requested
stage (what fusion needs: the stage images must be line-aligned), a pass needs
``K = L + max(stages) - 1`` frames; a ``reproduce`` run of ``L`` lines with ``M`` sensor rows
uses ``K = L + M - 1`` frames, which covers every stage ``1 .. M``. Pass ``lines=L`` to
:func:`dtdi_direct` / :func:`run_dtdi` to get exactly lines ``0 .. L-1`` for every stage.

Output word
-----------
The stored stage value is an integer word of ``beta_bits`` bits: ``Phi_FS = 2**beta``
(paper eq. 4) and the value is clipped to ``0 .. 2**beta - 1``::

    gamma = clip(rint(sum_i (v_i - b) + pedestal), 0, 2**beta - 1)     (subtract_black=True)
    gamma = clip(rint(sum_i v_i + pedestal), 0, 2**beta - 1)           (subtract_black=False)

with ``b`` the black offset [DN]: subtracted from every row before the sum (so it does not
accumulate), or left in, in which case stage ``m`` carries ``m * b``. Rounding only matters for
non-integer input (the sensor's ``quantization`` switched off) or a non-integer black offset.
``pedestal`` (one value, or one per stage) is a constant added after the sum and kept in the
word: the configured ``dtdi.pedestal_dn`` (default 64 DN, the default of
:func:`bench_sim.sensor.stream.sensor_dtdi_pass`; the low-level functions here default to 0,
the paper's plain word). It keeps the dark signal's noise above 0 DN, so the word does not clip
it and dark statistics stay unbiased (EMVA 1288 also requires an unclipped dark signal); every
consumer subtracts it (:func:`bench_sim.sensor.model.stage_offset_dn`). The sum is
exact for integer DN: :func:`dtdi_direct` forms it in float64 (``2**53`` is far above any sum of
16-bit rows), :class:`DTDIAccumulator` in ``uint32`` for words of up to 16 bits (``int64`` for
other integers), so the streaming and direct forms agree bit for bit. Non-integer DN are summed
in float64 by both, row ``0`` first, in the same order.

Noise: every row is read (and its read noise and quantisation noise added) independently, so
unlike charge-domain TDI the temporal dark noise of stage ``m`` grows as ``sqrt(m)``. Fixed
patterns of a column (the column amplifier offset, and the PRNU/DSNU of the ``m`` summed pixels)
are the same for every line, so they add coherently (the column offset as ``m`` times).

Memory: :class:`DTDIAccumulator` keeps the ``max(stages) - 1`` partial line sums of ``N``
columns (in a buffer of a few chunks more), ``O((M + C) * N)`` for chunks of ``C`` frames,
independent of the number of lines.

References
----------
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), eq. 1-4 (DTDI sums and the output word ``Phi_FS = 2**beta``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.sensor.diagonal_sums import diagonal_sums, stage_blocks
from bench_sim.sensor.model import (
    check_beta_bits,
    full_scale_dn,
    stage_dark_std_dn,
    stage_mean_var_dn,
    stage_offset_dn,
    word_clip_dn,
)

__all__ = [
    "DTDIAccumulator",
    "dtdi_direct",
    "run_dtdi",
    "collect_stage_lines",
    "full_scale_dn",
    "complete_lines",
    "frames_needed",
    "validate_stages",
    "check_stages",
    "check_stage_subset",
    "word_shift_dn",
    "stage_pedestals",
    "stage_mean_var_dn",
    "stage_dark_std_dn",
    "stage_offset_dn",
]


def complete_lines(n_frames: int, stage: int) -> int:
    """Number of complete lines of stage ``m`` in a pass of ``K`` frames: ``max(K - m + 1, 0)``."""
    return max(int(n_frames) - int(stage) + 1, 0)


def frames_needed(n_lines: int, stages: Iterable[int]) -> int:
    """Frames a pass needs for lines ``0 .. L-1`` of every stage: ``L + max(stages) - 1``."""
    return int(n_lines) + max(int(m) for m in stages) - 1


def validate_stages(stages: Iterable[int], rows: int | None = None) -> tuple[int, ...]:
    """Sorted unique stages; each an integer in ``1 .. rows``. Raises :class:`BenchSimError`."""
    try:
        out = sorted({int(m) for m in stages})
    except (TypeError, ValueError):
        raise BenchSimError(f"stages = {stages!r}: must be integers >= 1") from None
    if not out:
        raise BenchSimError("stages: at least one stage is needed")
    if out[0] < 1 or (rows is not None and out[-1] > rows):
        top = rows if rows is not None else "rows"
        raise BenchSimError(f"stages = {out}: each stage must lie in 1..{top}")
    return tuple(out)


def check_stages(
    stages: Iterable[int] | str, rows: int, what: str = "stages", given: str | None = None
) -> tuple[int, ...]:
    """Validate requested stages: integers in ``1 .. rows``, no duplicates; ``"all"`` means
    ``1 .. rows``. Returns them sorted; raises :class:`BenchSimError` (one line) otherwise,
    quoting ``given`` (what the user wrote, e.g. the ``--stages`` text) or the stages."""
    if isinstance(stages, str):
        if stages.strip() == "all":
            return tuple(range(1, rows + 1))
        raise BenchSimError(f"{what} = {stages!r}: expected a list of stages or 'all'")
    try:
        items = list(stages)
    except TypeError:
        raise BenchSimError(f"{what} = {stages!r}: expected a list of stages or 'all'") from None
    shown = given if given is not None else repr(items)
    if not items:
        raise BenchSimError(f"{what}: at least one stage is needed")
    out = []
    for m in items:
        if isinstance(m, bool) or not isinstance(m, int | np.integer):
            raise BenchSimError(f"{what} = {shown}: {m!r} is not an integer stage")
        out.append(int(m))
    dup = sorted({m for m in out if out.count(m) > 1})
    if dup:
        raise BenchSimError(f"{what} = {shown}: stage {dup[0]} is given twice (each stage once)")
    bad = [m for m in out if not 1 <= m <= rows]
    if bad:
        raise BenchSimError(f"{what} = {shown}: stage {bad[0]} outside 1..{rows} (sensor.rows = {rows})")
    return tuple(sorted(out))


def check_stage_subset(given: Iterable[int], stages: Sequence[int], what: str) -> tuple[int, ...]:
    """Validate ``given`` (:func:`check_stages`) as some of ``stages``; returns them sorted."""
    st = tuple(int(m) for m in stages)
    out = check_stages(list(given), max(st), what=what)
    if not set(out) <= set(st):
        raise BenchSimError(f"{what} = {list(out)}: each must be one of the pass's stages {list(st)}")
    return out


Pedestal = float | Mapping[int, float]


def stage_pedestals(pedestal_dn: Pedestal, stages: Sequence[int]) -> dict[int, float]:
    """The pedestal [DN] of every stage: one value for all, or a stage -> value mapping."""
    if isinstance(pedestal_dn, Mapping):
        missing = [m for m in stages if m not in pedestal_dn]
        if missing:
            raise BenchSimError(f"pedestal_dn: no value for stages {missing}")
        out = {m: float(pedestal_dn[m]) for m in stages}
    else:
        out = {m: float(pedestal_dn) for m in stages}
    bad = {m: v for m, v in out.items() if not np.isfinite(v)}
    if bad:
        raise BenchSimError(f"pedestal_dn = {bad}: must be finite")
    return out


def word_shift_dn(stage: int, black_offset_dn: float, subtract_black: bool, pedestal_dn: float) -> float:
    """The shift [DN] added to stage ``m``'s row sum to make its word (eq. 4): the pedestal
    ``P``, less ``m b`` when the black offset is subtracted."""
    return float(pedestal_dn) - (stage * float(black_offset_dn) if subtract_black else 0.0)


def _finish(
    sums: np.ndarray, stage: int, beta_bits: int, black_offset_dn: float, subtract_black: bool,
    pedestal_dn: float,
) -> np.ndarray:
    """Raw row sums -> stored words: subtract m*b, add the pedestal, round, clip (eq. 4)."""
    shift = word_shift_dn(stage, black_offset_dn, subtract_black, pedestal_dn)
    val = sums.astype(np.float64)  # exact for the integer sums of the accumulator
    if shift != 0.0:
        val += shift
    np.rint(val, out=val)
    np.clip(val, 0.0, float(word_clip_dn(beta_bits)), out=val)
    return val.astype(np.uint32)


def dtdi_direct(
    frames_dn: np.ndarray,
    stages: Sequence[int],
    beta_bits: int,
    black_offset_dn: float,
    subtract_black: bool = True,
    *,
    pedestal_dn: Pedestal = 0.0,
    lines: int | None = None,
) -> dict[int, np.ndarray]:
    """Reference DTDI straight from paper eq. 1-2 (the whole pass in memory).

    ``gamma_m[j] = sum_{i=0}^{m-1} v[j + i, i]`` for the complete lines ``j = 0 .. K - m``.

    Parameters
    ----------
    frames_dn
        (K, M, N) raw pixel values [DN] (frame, sensor row, column).
    stages
        Requested stages ``m`` (each in ``1 .. M``).
    beta_bits
        Output word size ``beta``: values clipped to ``0 .. 2**beta - 1`` (eq. 4).
    black_offset_dn
        Black offset ``b`` [DN] of the raw values.
    subtract_black
        Subtract ``b`` from every row before summing (else stage ``m`` carries ``m * b``).
    pedestal_dn
        Constant added to every stage value after the sum [DN]: one value, or stage -> value.
    lines
        ``None``: every stage gets all its complete lines (``K - m + 1``). An integer ``L``: every
        stage gets lines ``0 .. L-1`` (needs ``K >= L + max(stages) - 1``).

    Returns
    -------
    dict
        Stage ``m`` -> (lines, N) ``uint32`` stage image, row ``j`` = scene line ``j``.
    """
    v = np.asarray(frames_dn)
    if v.ndim != 3:
        raise BenchSimError(f"frames_dn shape {v.shape}: expected (frames, rows, columns)")
    n_frames, rows, _ = v.shape
    beta = check_beta_bits(beta_bits)
    st = validate_stages(stages, rows)
    if lines is not None and n_frames < frames_needed(lines, st):
        raise BenchSimError(
            f"lines = {lines}: a pass of {n_frames} frames gives only "
            f"{complete_lines(n_frames, st[-1])} complete lines of stage {st[-1]} "
            f"(needs {frames_needed(lines, st)} frames)"
        )
    ped = stage_pedestals(pedestal_dn, st)
    out: dict[int, np.ndarray] = {}
    for m in st:
        n_lines = complete_lines(n_frames, m) if lines is None else int(lines)
        sums = np.zeros((n_lines, v.shape[2]), dtype=np.float64)
        for i in range(m):  # eq. 1-2: row i of frame j + i, for every line j at once
            sums += v[i : i + n_lines, i, :]
        out[m] = _finish(sums, m, beta, black_offset_dn, subtract_black, ped[m])
    return out


class DTDIAccumulator:
    """Streaming DTDI: push frames one by one (or in chunks), get stage lines as they complete.

    Keeps the ``R - 1`` partial sums (``R = max(stages)``) of the scene lines still under the
    used rows, in a buffer that a chunk of ``C`` frames extends by ``C`` new lines, so its memory
    is ``O((R + C) * N)`` whatever the number of lines. After frame ``k`` (0-based) is
    pushed, the line ``j = k - m + 1`` of every requested stage ``m`` is complete (if ``j >= 0``)
    and is returned; so stage ``m`` produces lines ``0, 1, 2, ...`` in order, one per frame, from
    frame ``m - 1`` on. Partial lines (see the module docstring) are never returned.

    Parameters
    ----------
    n_columns
        Columns ``N`` of the frames.
    stages
        Requested stages (each ``>= 1``); frames need at least ``max(stages)`` rows (extra rows
        are ignored).
    beta_bits, black_offset_dn, subtract_black, pedestal_dn
        As in :func:`dtdi_direct`.
    """

    def __init__(
        self,
        n_columns: int,
        stages: Sequence[int],
        beta_bits: int,
        black_offset_dn: float,
        subtract_black: bool = True,
        *,
        pedestal_dn: Pedestal = 0.0,
    ) -> None:
        if int(n_columns) < 1:
            raise BenchSimError(f"n_columns = {n_columns!r}: must be >= 1")
        self.n_columns = int(n_columns)
        self.stages = validate_stages(stages)
        self.beta_bits = check_beta_bits(beta_bits)
        self.black_offset_dn = float(black_offset_dn)
        self.subtract_black = bool(subtract_black)
        self.pedestal_dn = stage_pedestals(pedestal_dn, self.stages)
        self.ring_rows = self.stages[-1]
        self.reset()

    def reset(self) -> None:
        """Forget every partial line (start a new pass)."""
        # rows _origin .. _origin + R - 2 of _buf: the partial sums of lines k - R + 1 .. k - 1
        # (k = frames_seen), the lines still under the used rows; free rows follow them
        self._buf = np.zeros((2 * self.ring_rows, self.n_columns), dtype=np.uint32)
        self._origin = 0
        self.frames_seen = 0

    def lines_emitted(self, stage: int) -> int:
        """Lines of ``stage`` returned so far (the index of its next line)."""
        return complete_lines(self.frames_seen, stage)

    def _sum_dtype(self, dtype: np.dtype) -> np.dtype:
        """A dtype that sums ``R`` rows of ``dtype`` exactly (and holds the partial sums so far):
        uint32 for words of up to 16 bits, int64 for other integers, else float64."""
        want: np.dtype
        if dtype.kind in "bu" and dtype.itemsize <= 2 and self.ring_rows <= 1 << 16:
            want = np.dtype(np.uint32)
        elif dtype.kind in "biu":
            want = np.dtype(np.int64)
        else:
            want = np.dtype(np.float64)
        return np.promote_types(want, self._buf.dtype)

    def _window(self, n_frames: int, dtype: np.dtype) -> np.ndarray:
        """Rows for the partial lines plus ``n_frames`` new lines (zeroed), in ``dtype``: the
        buffer's row ``r`` is line ``frames_seen - R + 1 + r``."""
        keep = self.ring_rows - 1
        need = keep + n_frames
        o = self._origin
        if dtype != self._buf.dtype or need > len(self._buf):
            buf = np.empty((max(len(self._buf), keep + 2 * n_frames), self.n_columns), dtype=dtype)
            buf[:keep] = self._buf[o : o + keep]  # exact: into a wider or the same dtype
            self._buf, self._origin, o = buf, 0, 0
        elif o + need > len(self._buf):  # move the partial lines back to the front
            self._buf[:keep] = self._buf[o : o + keep]
            self._origin, o = 0, 0
        win = self._buf[o : o + need]
        win[keep:] = 0
        return win

    def push(self, frame_dn: np.ndarray) -> dict[int, np.ndarray]:
        """Add one (M, N) frame of raw pixel values [DN].

        Returns
        -------
        dict
            Stage ``m`` -> its next complete line, a (N,) ``uint32`` array (scene line
            ``lines_emitted(m) - 1`` after the call), for the stages that completed one.
        """
        f = np.asarray(frame_dn)
        if f.ndim != 2 or f.shape[1] != self.n_columns or f.shape[0] < self.ring_rows:
            raise BenchSimError(
                f"frame shape {f.shape}: expected (rows >= {self.ring_rows}, {self.n_columns})"
            )
        return {m: block[0] for m, block in self.push_many(f[None]).items() if len(block)}

    def push_many(self, frames_dn: np.ndarray) -> dict[int, np.ndarray]:
        """Add a (C, M, N) chunk of frames; return stage -> (lines completed, N) ``uint32``.

        Stage ``m``'s block holds its lines ``lines_emitted(m) - n .. lines_emitted(m) - 1``
        (in order); a stage that completed no line gets a (0, N) array.

        Row ``i`` of the chunk's frame ``t`` (frame ``k = k0 + t``) is added to line ``k - i``
        (:func:`bench_sim.sensor.diagonal_sums.diagonal_sums`, one compiled loop), every line
        getting its rows in the order ``i = 0, 1, ...`` as frame by frame; stage ``m`` of a line
        is its sum once row ``m - 1`` is in, turned into its word there. The blocks are views
        into one array of all stages' lines.
        """
        chunk = np.asarray(frames_dn)
        if chunk.ndim == 2:
            chunk = chunk[None]
        if chunk.ndim != 3:
            raise BenchSimError(f"frames shape {chunk.shape}: expected (frames, rows, columns)")
        n_frames = chunk.shape[0]
        if n_frames and (chunk.shape[2] != self.n_columns or chunk.shape[1] < self.ring_rows):
            raise BenchSimError(
                f"frame shape {chunk.shape[1:]}: expected (rows >= {self.ring_rows}, {self.n_columns})"
            )
        r_rows, k0 = self.ring_rows, self.frames_seen
        if n_frames == 0:
            return {m: np.zeros((0, self.n_columns), dtype=np.uint32) for m in self.stages}
        win = self._window(n_frames, self._sum_dtype(chunk.dtype))
        blocks, emit_from, out_row0 = stage_blocks(self.stages, k0, n_frames, r_rows)
        # all stages' lines in one array (the blocks are views into it)
        words = np.empty((max(b.stop for b in blocks.values()), self.n_columns), dtype=np.uint32)
        out = {m: words[b] for m, b in blocks.items()}
        shifts = np.zeros(r_rows, dtype=np.float64)
        for m in self.stages:
            shifts[m - 1] = word_shift_dn(m, self.black_offset_dn, self.subtract_black, self.pedestal_dn[m])
        top = float(word_clip_dn(self.beta_bits))
        diagonal_sums(chunk, r_rows, win, words, emit_from, out_row0, shifts, top)
        self._origin += n_frames
        self.frames_seen = k0 + n_frames
        return out


def _iter_chunks(frames: np.ndarray | Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    if isinstance(frames, np.ndarray):
        if frames.ndim != 3:
            raise BenchSimError(f"frames shape {frames.shape}: expected (frames, rows, columns)")
        yield frames
        return
    for item in frames:
        arr = np.asarray(item)
        yield arr[None] if arr.ndim == 2 else arr


def run_dtdi(
    frames: np.ndarray | Iterable[np.ndarray],
    stages: Sequence[int],
    beta_bits: int,
    black_offset_dn: float,
    subtract_black: bool = True,
    *,
    pedestal_dn: Pedestal = 0.0,
    lines: int | None = None,
) -> dict[int, np.ndarray]:
    """Run a whole pass through :class:`DTDIAccumulator` (streaming, one pass, all stages).

    Parameters
    ----------
    frames
        A (K, M, N) array, or an iterable of (M, N) frames and/or (C, M, N) chunks in frame order.
    stages, beta_bits, black_offset_dn, subtract_black, pedestal_dn, lines
        As in :func:`dtdi_direct`; the result is identical to :func:`dtdi_direct` on the
        stacked frames.

    Returns
    -------
    dict
        Stage ``m`` -> (lines, N) ``uint32`` stage image.
    """
    st = validate_stages(stages)

    def pushed() -> Iterator[dict[int, np.ndarray]]:
        acc: DTDIAccumulator | None = None
        for chunk in _iter_chunks(frames):
            if chunk.ndim != 3:
                raise BenchSimError(f"frame chunk shape {chunk.shape}: expected (rows, columns) frames")
            if acc is None:
                acc = DTDIAccumulator(
                    chunk.shape[2], st, beta_bits, black_offset_dn, subtract_black, pedestal_dn=pedestal_dn
                )
            yield acc.push_many(chunk)
        if acc is None:
            raise BenchSimError("frames: the pass has no frames")

    return collect_stage_lines(pushed(), st, lines)


def collect_stage_lines(
    blocks: Iterable[dict[int, np.ndarray]], stages: Sequence[int], lines: int | None = None
) -> dict[int, np.ndarray]:
    """Join the per-chunk stage blocks of a streaming pass into whole stage images.

    Parameters
    ----------
    blocks
        Per chunk, stage ``m`` -> (n, N) block of its next complete lines, in line order (what
        :meth:`DTDIAccumulator.push_many` returns).
    stages
        The stages of the pass (validated, sorted).
    lines
        ``None``: keep every complete line; ``L``: lines ``0 .. L-1`` of every stage (an error
        if the pass gave fewer).
    """
    st = tuple(stages)
    kept_blocks: dict[int, list[np.ndarray]] = {m: [] for m in st}
    kept = {m: 0 for m in st}
    n_columns = 0
    for got in blocks:
        for m, block in got.items():
            n_columns = block.shape[1]
            if lines is not None:
                block = block[: max(int(lines) - kept[m], 0)]
            if len(block):
                kept_blocks[m].append(block)
                kept[m] += len(block)
    if lines is not None and min(kept.values()) < int(lines):
        raise BenchSimError(
            f"lines = {lines}: the pass gives only {kept[st[-1]]} complete lines of stage "
            f"{st[-1]} (needs {frames_needed(int(lines), st)} frames)"
        )
    return {
        m: (np.concatenate(b) if b else np.zeros((0, n_columns), dtype=np.uint32))
        for m, b in kept_blocks.items()
    }
