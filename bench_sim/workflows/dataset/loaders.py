"""Loaders for training: a dataset's samples by split, in batches, with or without PyTorch.

- :func:`iter_batches` (numpy, no framework): one epoch of batches of a split, each a dict
  ``field -> array (batch, ...)`` plus ``sample`` (the indices); shuffled per epoch by
  ``SeedSequence(seed, spawn_key=(epoch,))``, so an epoch's order depends only on
  ``(seed, epoch)``; ``shard = (k, n)`` gives worker ``k`` of ``n`` every ``n``-th batch.
- :class:`SplitSamples`: a map-style dataset (``len``, ``[j]`` -> dict of numpy arrays) of a
  split; picklable (each process opens the store itself), so it works with any number of
  loader workers.
- :func:`torch_dataset`: :class:`SplitSamples` with PyTorch tensors (``torch`` is an optional
  dependency: ``pip install bench-sim[torch]``); use it with ``torch.utils.data.DataLoader``.
  JAX and others take the numpy arrays of :func:`iter_batches` directly.

The split of each sample is recorded in ``dataset.json`` (``splits``) and the manifest
(column ``split``), and recomputed here from them (:mod:`bench_sim.workflows.dataset.splits`).
Words (``dn``, unsigned) come as ``int64`` tensors (PyTorch's unsigned types are partial).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.workflows.dataset.reader import DATA_STORE, complete_samples, read_info, read_sample_array
from bench_sim.workflows.dataset.splits import DEFAULT_SPLITS, split_indices

__all__ = ["SplitSamples", "iter_batches", "torch_dataset", "split_samples"]


def split_samples(folder: str | Path, split: str | None = None, *, incomplete: bool = False) -> list[int]:
    """The complete samples of ``split`` (``None``: every split), sorted; one-line error for an
    unknown split or an incomplete dataset (unless ``incomplete``)."""
    info = read_info(folder)
    done = complete_samples(folder)
    n = int(info["samples"])
    if not incomplete and len(done) < n:
        raise BenchSimError(
            f"{str(folder)!r}: incomplete dataset ({len(done)} of {n} samples complete): complete it with "
            "--resume, or load its complete samples with incomplete=True"
        )
    splits = info.get("splits") or DEFAULT_SPLITS
    if split is None:
        return done
    if split not in splits:
        raise BenchSimError(f"split = {split!r}: not a split of {str(folder)!r} ({', '.join(splits)})")
    chosen = set(split_indices(int(info["seed"]), n, splits)[split])
    return [i for i in done if i in chosen]


class SplitSamples:
    """Map-style dataset of one split: ``len(ds)``, ``ds[j]`` -> ``{field: array, "sample": i}``.

    Parameters
    ----------
    folder
        The dataset folder.
    split
        ``train``, ``val``, ``test`` or another split of the spec (``None``: all samples).
    fields
        Variables to read (default: all of the dataset's variables).
    incomplete
        Allow an incomplete dataset (its complete samples).
    """

    def __init__(self, folder: str | Path, split: str | None = None, fields: Sequence[str] | None = None,
                 *, incomplete: bool = False) -> None:
        self.folder = Path(folder)
        info = read_info(self.folder)
        schema = info["schema"]["variables"]
        self.fields = tuple(schema) if fields is None else tuple(fields)
        unknown = [f for f in self.fields if f not in schema]
        if unknown or not self.fields:
            raise BenchSimError(
                f"fields = {list(self.fields)}: {unknown[0] if unknown else 'none'!r} is not a variable of "
                f"the dataset ({', '.join(schema)})"
            )
        self.units = {f: schema[f]["units"] for f in self.fields}
        self.split = split
        self.indices = tuple(split_samples(self.folder, split, incomplete=incomplete))
        self._group: Any = None

    def __len__(self) -> int:
        return len(self.indices)

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_group": None}  # each process opens the store itself

    def _store(self) -> Any:
        if self._group is None:
            import zarr

            self._group = zarr.open_group(str(self.folder / DATA_STORE), mode="r")
        return self._group

    def read(self, index: int) -> dict[str, np.ndarray]:
        """The fields of sample ``index`` (a dataset index, not a position in the split).

        A chunk that cannot be read (a damaged file) is one line naming the sample, the
        variable and the chunk's file (:class:`~bench_sim.errors.BenchSimError`)."""
        group = self._store()
        return {f: read_sample_array(group, self.folder, f, int(index)) for f in self.fields}

    def __getitem__(self, j: int) -> dict[str, Any]:
        i = self.indices[j]
        return {**self.read(i), "sample": i}


def iter_batches(
    folder: str | Path,
    *,
    split: str | None = None,
    fields: Sequence[str] | None = None,
    batch_size: int = 8,
    shuffle: bool = True,
    seed: int = 0,
    epoch: int = 0,
    drop_last: bool = False,
    shard: tuple[int, int] = (0, 1),
    incomplete: bool = False,
) -> Iterator[dict[str, np.ndarray]]:
    """One epoch of batches of a split as numpy arrays (no framework needed).

    Each batch is ``{field: array (b, ...), "sample": int64 array (b,)}``, ``b = batch_size``
    (the last batch smaller unless ``drop_last``). With ``shuffle`` the order of the epoch is
    ``default_rng(SeedSequence(seed, spawn_key=(epoch,))).permutation`` of the split's samples,
    else sorted; worker ``k`` of ``n`` (``shard = (k, n)``) gets batches ``k, k + n, ...`` of that
    order, so ``n`` workers together see every sample of the split exactly once per epoch.
    """
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise BenchSimError(f"batch_size = {batch_size!r}: an integer >= 1 is needed")
    k, n = (int(v) for v in shard)
    if not (n >= 1 and 0 <= k < n):
        raise BenchSimError(f"shard = {shard!r}: expected (k, n) with 0 <= k < n")
    if int(epoch) < 0 or int(seed) < 0:
        raise BenchSimError(f"seed = {seed}, epoch = {epoch}: both must be >= 0")
    ds = SplitSamples(folder, split, fields, incomplete=incomplete)
    order = np.asarray(ds.indices, dtype=np.int64)
    if shuffle:
        rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(epoch),)))
        order = rng.permutation(order)
    starts = range(0, len(order), batch_size)
    for b, start in enumerate(starts):
        chunk = order[start : start + batch_size]
        if b % n != k or (drop_last and len(chunk) < batch_size):
            continue
        items = [ds.read(int(i)) for i in chunk]
        batch = {f: np.stack([it[f] for it in items]) for f in ds.fields}
        batch["sample"] = chunk.copy()
        yield batch


class _TorchSamples(SplitSamples):
    """:class:`SplitSamples` returning PyTorch tensors (unsigned words as ``int64``)."""

    def __getitem__(self, j: int) -> dict[str, Any]:
        import torch

        item = super().__getitem__(j)
        out: dict[str, Any] = {}
        for name, value in item.items():
            arr = np.asarray(value)
            if arr.dtype.kind == "u":
                arr = arr.astype(np.int64)
            out[name] = torch.from_numpy(np.ascontiguousarray(arr))
        return out


def torch_dataset(
    folder: str | Path, split: str | None = None, fields: Sequence[str] | None = None, *,
    incomplete: bool = False,
) -> SplitSamples:
    """A map-style PyTorch dataset of a split (``torch.utils.data.DataLoader(ds, batch_size=...,
    shuffle=True, num_workers=...)``): items are dicts of tensors and the sample index.

    Raises a one-line :class:`BenchSimError` when PyTorch is not installed (it is optional:
    ``pip install bench-sim[torch]``; :func:`iter_batches` needs no framework).
    """
    try:
        import torch  # noqa: F401
    except ImportError:
        raise BenchSimError(
            "torch_dataset: PyTorch is not installed (pip install 'bench-sim[torch]'); iter_batches "
            "gives the same batches as numpy arrays"
        ) from None
    return _TorchSamples(folder, split, fields, incomplete=incomplete)
