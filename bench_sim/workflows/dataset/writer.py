"""The write side of a ``bench-sim dataset`` run: the folder made ready once, each sample written
as it arrives.

- :class:`DatasetFolder` lays out a new dataset (:func:`~bench_sim.workflows.dataset.store.lay_out`:
  a temporary folder renamed into place) or takes the same dataset again (``--resume``,
  ``--only``), and removes its completion record, once. On a cluster this runs while the first
  samples are made (the run's ``meanwhile``): laying out imports xarray and Zarr and writes the
  empty store (about 1 s), which the workers would otherwise wait for.
- :class:`SampleWriter` writes a sample's arrays into ``data.zarr``, then its record
  ``samples/NNNNNNNN.json`` (a record says its arrays are on disk), and the manifest every
  :data:`MANIFEST_EVERY_S` seconds.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.runtime.execution import TaskOutcome
from bench_sim.runtime.progress import ProgressBar
from bench_sim.workflows.dataset.reader import COMPLETION_RECORD, DATA_STORE, journal
from bench_sim.workflows.dataset.spec import DatasetSpec
from bench_sim.workflows.dataset.splits import split_map
from bench_sim.workflows.dataset.store import lay_out, write_manifest
from bench_sim.workflows.dataset.targets import strict_json

__all__ = ["DatasetFolder", "SampleWriter", "MANIFEST_EVERY_S"]

#: Seconds between manifest rewrites during a run
MANIFEST_EVERY_S = 10.0


@dataclass
class DatasetFolder:
    """The dataset folder ``out`` of a checked run, made ready by :meth:`prepare`.

    Attributes
    ----------
    spec, out
        The dataset and its folder.
    action
        ``create`` (lay out a new dataset) or ``reuse`` (the same dataset:
        :func:`~bench_sim.workflows.dataset.store.check_folder`).
    ready
        Whether :meth:`prepare` has run: from then on a stopped run leaves a dataset that
        ``--resume`` finishes.
    """

    spec: DatasetSpec
    out: Path
    action: str
    ready: bool = field(default=False, init=False)

    def prepare(self) -> None:
        """Lay out (``create``) or keep (``reuse``) the folder and remove its completion record
        (written again last if the dataset completes); once, later calls do nothing."""
        if self.ready:
            return
        if self.action == "create":
            lay_out(self.spec, self.out)
        (self.out / COMPLETION_RECORD).unlink(missing_ok=True)
        self.ready = True


class SampleWriter:
    """Writes each outcome as it arrives: arrays into ``data.zarr``, then the record (the
    journal, :mod:`bench_sim.runtime.journal`); the manifest every :data:`MANIFEST_EVERY_S`
    seconds; advances the progress bar. The folder must be ready (:meth:`DatasetFolder.prepare`)
    by the first outcome."""

    def __init__(self, out: Path, spec: DatasetSpec, values: Sequence[dict[str, Any]], meta: dict[str, Any],
                 bar: ProgressBar):
        self.out, self.spec, self.values, self.meta, self.bar = out, spec, values, meta, bar
        self.journal = journal(out)
        self.splits = split_map(spec.seed, spec.samples, spec.splits)
        self.ran: list[int] = []
        self.failed: dict[int, str] = {}
        self._last_manifest = time.monotonic()

    @functools.cached_property
    def group(self) -> Any:
        """``data.zarr``'s group of arrays, by name (opened at the first sample)."""
        import zarr

        return zarr.open_group(str(self.out / DATA_STORE), mode="r+", use_consolidated=False)

    def write(self, outcome: TaskOutcome) -> None:
        """Write one sample's outcome (a ``SampleOutput`` of
        :func:`~bench_sim.workflows.dataset.run.make_sample`, or its error)."""
        i = int(outcome.index)
        # --only on a complete sample: not complete while it is rewritten
        self.journal.path(i).unlink(missing_ok=True)
        rec: dict[str, Any] = {
            "sample": i, "seed": self.spec.seed,
            "values": self.values[i],
            "split": self.splits[i],
            "spec_sha256": self.spec.identity(),  # --resume takes only this spec's and seed's records
            "wall_s": round(float(outcome.wall_s), 4), "worker": str(outcome.worker),
        }
        if outcome.ok:
            value = outcome.value
            with deferred_interrupts():  # Zarr writes on its own thread: never cut (docs/reliability.md)
                for name, arr in value.arrays.items():
                    self.group[name][i] = np.asarray(arr, dtype=self.group[name].dtype)
            rec.update(status="complete", metrics=value.metrics, **value.info)
        else:
            rec.update(status="failed", error=outcome.error)
            self.failed[i] = str(outcome.error)
            self.bar.note(f"{len(self.failed)} failed")
        self.journal.write(strict_json(rec))  # after the arrays: a record says they are on disk
        self.ran.append(i)
        self.bar.advance()
        if time.monotonic() - self._last_manifest > MANIFEST_EVERY_S:
            write_manifest(self.out, self.spec, self.meta, self.values)
            self._last_manifest = time.monotonic()
