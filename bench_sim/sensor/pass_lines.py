"""Completed lines of a pass, assembled per stage and handed to a sink.

The streaming pass yields, per chunk of frames, the stage words of the lines it completed
(:func:`bench_sim.sensor.stream.iter_stream`) and, from :class:`bench_sim.sensor.pass_truth.PassTruth`,
their truth (the reflectance a band of lines later). :class:`LineAssembler` joins them: once every
variable of a stage holds a line, the line goes to the sink (:class:`PassSink`) with the word's clip
added to ``clipped``, each variable cast to its dtype, and the lines of both fusion stages go
through the fusion callback (an image variable per line). Only the lines in flight are held, so a
sink that writes them out (a Zarr store, :mod:`bench_sim.workflows.simulate_store`) keeps the
memory of a pass flat in the number of lines; :class:`ArraySink` keeps them in (stage, line,
column) arrays.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

import numpy as np

__all__ = ["PassSink", "ArraySink", "LineAssembler", "FuseLines"]

#: the fusion of a pass's two stages: ``f(lines_mu1, lines_mu2)`` -> image variable -> its lines
FuseLines = Callable[[dict[str, np.ndarray], dict[str, np.ndarray]], dict[str, np.ndarray]]


class PassSink(Protocol):
    """Receives consecutive lines of the pass's variables."""

    def write(self, name: str, stage: int | None, line0: int, block: np.ndarray) -> None:
        """Lines ``line0 .. line0 + len(block) - 1`` of variable ``name``: of stage ``stage``
        ((n, N) block), or of an image variable (``stage`` None)."""


class ArraySink:
    """A :class:`PassSink` into in-memory arrays: ``arrays[name]`` is (stages, lines, columns)
    for a stage variable, (lines, columns) for an image variable, of the given dtypes.
    ``stages_of``: the stages a stage variable has when not all (the truth of some stages only);
    its array then holds those, in that order."""

    def __init__(
        self, stages: Sequence[int], lines: int, columns: int, stage_dtypes: Mapping[str, np.dtype],
        image_dtypes: Mapping[str, np.dtype], stages_of: Mapping[str, Sequence[int]] | None = None,
    ) -> None:
        held = {n: tuple(int(m) for m in (stages_of or {}).get(n, stages)) for n in stage_dtypes}
        self.index = {n: {m: s for s, m in enumerate(st)} for n, st in held.items()}
        self.arrays = {n: np.empty((len(held[n]), lines, columns), dtype=dt)
                       for n, dt in stage_dtypes.items()}
        self.arrays.update({n: np.empty((lines, columns), dtype=dt) for n, dt in image_dtypes.items()})

    def write(self, name: str, stage: int | None, line0: int, block: np.ndarray) -> None:
        target = self.arrays[name] if stage is None else self.arrays[name][self.index[name][stage]]
        target[line0 : line0 + len(block)] = block


class LineAssembler:
    """Joins the words and the truth of each stage line by line and hands complete lines to a sink.

    Parameters
    ----------
    stages
        The pass's stages.
    dtypes
        Stage variable -> its dtype: ``dn`` and, with the truth, ``mean_dn``, ``linear_dn``,
        ``photons``, ``reflectance``, ``clipped``. A stage's line leaves once all of them hold it.
    sink
        Where the lines go.
    word_top
        ``2**beta - 1`` [DN]: a word there is ``clipped``.
    fuse
        ``(mu1, mu2, f)``: ``f(lines_mu1, lines_mu2)`` -> image variable -> (n, N) lines, called
        with the same lines of both stages (variable -> (n, N) lines, as the sink got them) as
        they complete; or None.
    stages_of
        Stage variable -> its stages, for a variable that not every stage has (the truth of
        some stages only; default: all ``stages``). A stage's line leaves once the variables
        of that stage hold it.
    """

    def __init__(
        self, stages: Sequence[int], dtypes: Mapping[str, np.dtype], sink: PassSink, word_top: float,
        fuse: tuple[int, int, FuseLines] | None = None, stages_of: Mapping[str, Sequence[int]] | None = None,
    ) -> None:
        self.dtypes, self.sink, self.word_top, self.fuse = dict(dtypes), sink, word_top, fuse
        self.stages = tuple(int(m) for m in stages)
        held = {n: {int(m) for m in (stages_of or {}).get(n, self.stages)} for n in dtypes}
        #: stage -> the variables it has
        self.names = {m: [n for n in dtypes if m in held[n]] for m in self.stages}
        keys = [(n, m) for m in self.stages for n in self.names[m]]
        self.pending: dict[tuple[str, int], list[np.ndarray]] = {key: [] for key in keys}
        self.received = {key: 0 for key in self.pending}
        self.emitted = dict.fromkeys(self.stages, 0)
        #: stage -> the lines of its variables not fused yet (fusion stages only)
        self.fuse_lines: dict[int, list[dict[str, np.ndarray]]] = {}
        if fuse is not None:
            self.fuse_lines = {fuse[0]: [], fuse[1]: []}
        self.fused = 0

    def put(self, name: str, stage: int, line0: int, block: np.ndarray) -> None:
        """Lines ``line0 ..`` of ``name`` of ``stage``, continuing what was put before."""
        key = (name, int(stage))
        if line0 != self.received[key]:
            raise ValueError(f"{name} of stage {stage}: lines from {line0}, expected {self.received[key]}")
        if len(block):
            self.pending[key].append(block)
            self.received[key] += len(block)
            self._flush(int(stage))

    def _flush(self, m: int) -> None:
        upto = min(self.received[(n, m)] for n in self.names[m])
        j0 = self.emitted[m]
        if upto <= j0:
            return
        lines = {n: self._take(n, m, upto - j0) for n in self.names[m]}
        if "clipped" in lines:
            lines["clipped"] = lines["clipped"] | (lines["dn"] >= self.word_top)
        lines = {n: block.astype(self.dtypes[n], copy=False) for n, block in lines.items()}
        for n, block in lines.items():
            self.sink.write(n, m, j0, block)
        self.emitted[m] = upto
        if m in self.fuse_lines:
            self.fuse_lines[m].append(lines)
            self._fuse()

    def _take(self, name: str, m: int, n: int) -> np.ndarray:
        """The first ``n`` pending lines of ``name`` of stage ``m``."""
        parts = self.pending[(name, m)]
        joined = parts[0] if len(parts) == 1 else np.concatenate(parts)
        rest = joined[n:]
        self.pending[(name, m)] = [rest] if len(rest) else []
        return joined[:n]

    def _fuse(self) -> None:
        assert self.fuse is not None
        mu1, mu2, f = self.fuse
        n = min(sum(len(b["dn"]) for b in self.fuse_lines[mu]) for mu in (mu1, mu2))
        if n == 0:
            return
        both = []
        for mu in (mu1, mu2):
            parts = self.fuse_lines[mu]
            joined = parts[0]
            if len(parts) > 1:
                joined = {k: np.concatenate([p[k] for p in parts]) for k in joined}
            both.append({k: v[:n] for k, v in joined.items()})
            self.fuse_lines[mu] = [{k: v[n:] for k, v in joined.items()}] if len(joined["dn"]) > n else []
        for name, block in f(both[0], both[1]).items():
            self.sink.write(name, None, self.fused, block)
        self.fused += n
