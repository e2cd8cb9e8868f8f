"""Execution layer: many independent runs of the chain on ``dask.distributed``.

Sweeps (one task per parameter point) and datasets (one task per sample) run here, on a
``LocalCluster`` of worker processes by default or on an existing cluster given by its scheduler
address (``tcp://HOST:PORT``; start one with ``dask scheduler`` and ``dask worker ADDRESS`` on
each machine). One module serves both, so every experiment gets the same guarantees:

- **Determinism.** Task ``i`` of a run with root seed ``s`` draws from
  :func:`task_seed_sequence` ``(s, i)``, which is ``numpy.random.SeedSequence(s).spawn(n)[i]``:
  its result depends only on ``(s, i)`` and the task's own input, never on the number of workers,
  on which worker ran it or on the order of completion.
- **Failure isolation.** A task that raises is recorded as a :class:`TaskOutcome` with a one-line
  error; the other tasks go on.
- **Reuse inside a worker.** Worker processes live for the whole run; :func:`worker_cache` keeps
  expensive objects (Mitsuba scenes, compiled kernels, render records) between the tasks a worker
  runs, and the render module's own record cache is process-level too.
- **Shared inputs made once per run.** A task may name :class:`Shared` inputs (a fast engine's
  light records, a camera's measured dynamic range): each distinct one (by its key) is made
  once for the whole run, as a task of its own scheduled before the tasks that need it, and
  passed to them as extra arguments; Dask moves it to the worker that needs it (and prefers to
  run a task where its inputs already are), so a run of ``n`` workers makes it once, not ``n``
  times, and independent inputs are made side by side.
- **Results as they complete.** :func:`run_tasks` calls ``on_result`` in the client process as
  each task finishes, so callers write each point or sample as soon as it is done and a killed
  run can be resumed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from bench_sim.errors import BenchSimError, ClusterError
from bench_sim.runtime import collector
from bench_sim.runtime.cluster import (
    close_in_background,
    probe_scheduler,
    quiet_dask_logs,
    quiet_local_cluster,
    wait_for_workers,
)
from bench_sim.runtime.parallel import child_sequence

__all__ = [
    "check_workers",
    "TaskOutcome",
    "Shared",
    "task_seed_sequence",
    "task_generator",
    "open_client",
    "release_client",
    "run_tasks",
    "worker_cache",
    "default_workers",
]

T = TypeVar("T")

_CACHE: dict[str, Any] = {}


@dataclass(frozen=True)
class TaskOutcome:
    """What one task gave back.

    Attributes
    ----------
    index
        The task's index in the run (its position in ``args``).
    value
        The function's return value, or ``None`` if it failed.
    error
        ``None`` on success, else one line: ``"ErrorType: message"``.
    wall_s
        Wall time of the task inside the worker [s].
    worker
        Address of the worker that ran it (``"local"`` for in-process runs).
    """

    index: int
    value: Any
    error: str | None
    wall_s: float
    worker: str

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass(frozen=True)
class Shared:
    """An input that several tasks of a run need, made once per run (see the module docstring).

    Attributes
    ----------
    key
        Its identity: two ``Shared`` with the same key are the same input (made once).
    func
        A module-level (picklable) function of one argument that makes it; it must be a
        deterministic function of ``arg``.
    arg
        Its argument.
    """

    key: str
    func: Callable[[Any], Any]
    arg: Any


@dataclass(frozen=True)
class _SharedError:
    """What a shared input that failed is replaced by: the tasks that need it fail with ``error``."""

    error: str


def _make_shared(func: Callable[[Any], Any], arg: Any) -> Any:
    """Make a shared input (in a worker); a failure becomes a :class:`_SharedError`."""
    collector.settle_once()  # a worker's first task may be this one: settled before it makes garbage
    try:
        return func(arg)
    except Exception as exc:
        if os.environ.get("BENCH_SIM_DEBUG") == "1":
            traceback.print_exc()
        return _SharedError(_one_line(exc))


def task_seed_sequence(root_seed: int, index: int) -> np.random.SeedSequence:
    """The independent stream of task ``index`` under ``root_seed``.

    Equal to ``numpy.random.SeedSequence(root_seed).spawn(n)[index]`` for any ``n > index``
    (spawned children differ from their parent only by the spawn key), without spawning the
    ``index`` children before it: a resumed run or ``--only I`` regenerates task ``I`` alone.
    """
    if root_seed < 0 or index < 0:
        raise BenchSimError(f"seed = {root_seed}, index = {index}: both must be >= 0")
    return child_sequence(np.random.SeedSequence(int(root_seed)), index)


def task_generator(root_seed: int, index: int) -> np.random.Generator:
    """A ``numpy.random.Generator`` on :func:`task_seed_sequence` ``(root_seed, index)``."""
    return np.random.default_rng(task_seed_sequence(root_seed, index))


def worker_cache(key: str, factory: Callable[[], T]) -> T:
    """Return the object cached under ``key`` in this process, making it with ``factory`` once.

    Dask worker processes run many tasks; objects cached here (a Mitsuba scene, render records)
    survive between them. In the client process (``workers = 0``) it is an ordinary cache.
    """
    if key not in _CACHE:
        _CACHE[key] = factory()
    return _CACHE[key]


def default_workers() -> int:
    """Worker processes of a local cluster by default: the number of usable cores."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def _run_one(func: Callable[..., Any], index: int, arg: Any, *shared: Any) -> TaskOutcome:
    """Run one task (``func(arg, *shared)``), timing it and turning an exception into a one-line
    error; a failed shared input fails the task with its error."""
    try:
        from distributed import get_worker

        where = get_worker().address
    except (ImportError, ValueError):
        where = "local"
    collector.settle_once()  # a local cluster's worker: its task's modules are in (once per process)
    t0 = time.perf_counter()
    failed = next((s for s in shared if isinstance(s, _SharedError)), None)
    if failed is not None:
        return TaskOutcome(index, None, failed.error, 0.0, where)
    try:
        value = func(arg, *shared)
    except Exception as exc:  # a failed task is recorded and the run goes on
        if os.environ.get("BENCH_SIM_DEBUG") == "1":
            traceback.print_exc()
        return TaskOutcome(index, None, _one_line(exc), time.perf_counter() - t0, where)
    return TaskOutcome(index, value, None, time.perf_counter() - t0, where)


def check_workers(workers: int | None, scheduler: str | None) -> None:
    """Refuse ``--workers`` together with ``--scheduler`` and a negative ``--workers`` (one line
    each, before any work): the options of a sweep's or a design's points."""
    if workers is not None and scheduler is not None:
        raise BenchSimError(
            "--workers and --scheduler: give one of them (--scheduler uses that cluster's workers)"
        )
    if workers is not None and workers < 0:
        raise BenchSimError(f"--workers = {workers}: must be >= 0 (0 runs in this process)")


@contextlib.contextmanager
def open_client(
    workers: int | None = None, scheduler: str | None = None, *, connect_timeout_s: float | None = None
) -> Iterator[Any]:
    """A ``dask.distributed.Client`` for a run; ``None`` for in-process execution.

    Parameters
    ----------
    workers
        Worker processes of a new ``LocalCluster`` (one thread each; default
        :func:`default_workers`). ``0`` runs every task in this process, one after the other
        (no Dask at all: for debugging and for tiny runs).
    scheduler
        Address of a running scheduler (``tcp://HOST:PORT``); ``workers`` is then ignored. The
        address is checked, the scheduler's handshake awaited (:mod:`bench_sim.runtime.cluster`)
        and at least one worker waited for before the client is given.
    connect_timeout_s
        How long to wait for the scheduler's handshake [s] before giving up with a one-line
        error (default: ``BENCH_SIM_CONNECT_TIMEOUT_S``, else 10 s).

    Notes
    -----
    The client (and the local cluster) is closed on the way out, however the block ends: no
    unclosed socket is left for the interpreter to warn about.
    """
    if scheduler is None and workers == 0:
        yield None
        return
    with quiet_dask_logs():
        yield from _client(workers, scheduler, connect_timeout_s)


def release_client(client: Any) -> None:
    """Every task of the run is done: the client of a local cluster from :func:`open_client` is
    closed now (Dask is no longer the default scheduler of what the caller writes next) and its
    cluster starts closing on a thread of its own, so the caller writes its outputs while the
    worker processes stop, off the critical path; the ``with open_client(...)`` block's end waits
    for the close to finish (:func:`~bench_sim.runtime.cluster.close_in_background`). Nothing
    for ``None`` (in-process runs) or a ``--scheduler`` cluster."""
    close_in_background(client)


def _client(workers: int | None, scheduler: str | None, connect_timeout_s: float | None) -> Iterator[Any]:
    """:func:`open_client`'s body for a cluster (a generator for ``yield from``)."""
    if scheduler is not None:
        timeout = connect_timeout_s if connect_timeout_s is not None else _env_seconds(
            "BENCH_SIM_CONNECT_TIMEOUT_S", 10.0)
        probe_scheduler(scheduler, timeout)
        from distributed import Client

        try:
            client = Client(scheduler, timeout=f"{timeout}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise BenchSimError(
                f"--scheduler = {scheduler!r}: cannot reach a Dask scheduler there ({_one_line(exc)})"
            ) from None
        try:
            wait_s = _env_seconds("BENCH_SIM_WORKER_WAIT_S", 120.0)
            wait_for_workers(client, scheduler, grace_s=min(10.0, wait_s), timeout_s=wait_s)
            yield client
        finally:
            with contextlib.suppress(Exception):
                client.close(timeout=10)
        return
    n = default_workers() if workers is None else int(workers)
    if n < 0:
        raise BenchSimError(f"--workers = {n}: must be >= 0 (0 runs in this process)")
    with quiet_local_cluster(n) as client:
        yield client


def _env_seconds(name: str, default: float) -> float:
    """A duration [s] from the environment variable ``name`` (a positive number), else ``default``."""
    text = os.environ.get(name)
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0:
        raise BenchSimError(f"{name} = {text!r}: needs a number of seconds > 0")
    return value


def run_tasks(
    func: Callable[..., Any],
    args: Sequence[Any],
    *,
    client: Any,
    indices: Sequence[int] | None = None,
    on_result: Callable[[TaskOutcome], None] | None = None,
    keep_values: bool = True,
    shared: Sequence[Sequence[Shared]] | None = None,
    meanwhile: Callable[[], None] | None = None,
) -> list[TaskOutcome]:
    """Run ``func(arg, *inputs)`` for every ``arg`` and report each outcome as it completes.

    Parameters
    ----------
    func
        A module-level (picklable) function of one argument and its shared inputs. It must
        derive all its randomness from its argument (e.g. a seed from
        :func:`task_seed_sequence` carried in it).
    args
        One argument per task.
    client
        From :func:`open_client`; ``None`` runs the tasks here, in order.
    indices
        The task indices reported in :attr:`TaskOutcome.index` (default ``0 .. len(args)-1``);
        a resumed run passes the indices of the tasks still to do.
    on_result
        Called in this process with each outcome, in completion order.
    keep_values
        Keep each task's value in the returned outcomes. ``False`` drops it once ``on_result``
        has seen it (``value`` is ``None``), so a run whose tasks return large arrays that
        ``on_result`` writes away holds one result at a time, however many tasks it has.
    shared
        Per task, the :class:`Shared` inputs it needs (passed to ``func`` after ``arg``, in
        this order); each distinct key is made once for the run. Default: none.
    meanwhile
        On a cluster, called in this process (this thread) once every task is submitted, before
        the first outcome is awaited: work of this process that can overlap the tasks, such as
        importing what the outputs are written with (:mod:`bench_sim.runtime.preload`). Not
        called for in-process runs (``client`` ``None``).

    Returns
    -------
    list of TaskOutcome
        In the order of ``args``.

    Notes
    -----
    Each task's result is released on its worker as soon as this process has it, and each
    shared input as soon as the last task that needs it is done, so worker memory does not
    grow with the number of tasks.
    """
    idx = list(range(len(args))) if indices is None else [int(i) for i in indices]
    if len(idx) != len(args):
        raise BenchSimError(f"indices: {len(idx)} given for {len(args)} tasks")
    needs = [tuple(s) for s in shared] if shared is not None else [()] * len(args)
    if len(needs) != len(args):
        raise BenchSimError(f"shared: {len(needs)} given for {len(args)} tasks")
    outcomes: dict[int, TaskOutcome] = {}

    def record(out: TaskOutcome) -> None:
        if on_result is not None:
            on_result(out)
        outcomes[out.index] = out if keep_values else dataclasses.replace(out, value=None)

    if client is None:
        _run_here(func, idx, args, needs, record)
        return [outcomes[i] for i in idx]
    _run_on(client, func, idx, args, needs, record, outcomes, meanwhile)
    return [outcomes[i] for i in idx]


def _uses(needs: Sequence[tuple[Shared, ...]]) -> dict[str, int]:
    """Key -> number of tasks that need that shared input."""
    uses: dict[str, int] = {}
    for need in needs:
        for s in {s.key: s for s in need}.values():
            uses[s.key] = uses.get(s.key, 0) + 1
    return uses


def _run_here(
    func: Callable[..., Any], idx: list[int], args: Sequence[Any], needs: Sequence[tuple[Shared, ...]],
    record: Callable[[TaskOutcome], None],
) -> None:
    """:func:`run_tasks` in this process: each shared input made when first needed, dropped
    after its last task."""
    uses = _uses(needs)
    made: dict[str, Any] = {}
    for i, arg, need in zip(idx, args, needs, strict=True):
        for s in need:
            if s.key not in made:
                made[s.key] = _make_shared(s.func, s.arg)
        record(_run_one(func, i, arg, *(made[s.key] for s in need)))
        for key in {s.key for s in need}:
            uses[key] -= 1
            if uses[key] == 0:
                del made[key]


def _run_on(
    client: Any, func: Callable[..., Any], idx: list[int], args: Sequence[Any],
    needs: Sequence[tuple[Shared, ...]], record: Callable[[TaskOutcome], None],
    outcomes: dict[int, TaskOutcome], meanwhile: Callable[[], None] | None = None,
) -> None:
    """:func:`run_tasks` on a Dask client: the shared inputs first (at a higher priority), then
    the tasks, each depending on the futures of its inputs; ``meanwhile()`` once all are submitted."""
    from distributed import as_completed

    uses = _uses(needs)
    made: dict[str, Any] = {}
    for need in needs:
        for s in need:
            if s.key not in made:
                made[s.key] = client.submit(_make_shared, s.func, s.arg, pure=False, priority=1)
    if made:
        futures = [  # in the order given: Dask would start tasks whose inputs are ready in any order
            client.submit(_run_one, func, i, arg, *(made[s.key] for s in need), pure=False, priority=-k)
            for k, (i, arg, need) in enumerate(zip(idx, args, needs, strict=True))
        ]
    else:
        futures = client.map(_run_one, [func] * len(args), idx, list(args), pure=False)
    task_needs = {fut.key: {s.key for s in need} for fut, need in zip(futures, needs, strict=True)}
    pending = as_completed(futures)
    del futures
    try:
        if meanwhile is not None:
            meanwhile()
        for fut in pending:  # only ``pending`` holds the futures not yet done
            try:
                out = fut.result()  # a task's own exception is already an outcome (_run_one)
            except Exception as exc:  # so this is the cluster: the scheduler or the connection lost
                why = _one_line(exc)
                if "reason:" in why:  # "... cancelled for reason: scheduler-connection-lost."
                    why = why.rsplit("reason:", 1)[1].strip(" .")
                raise ClusterError(
                    f"lost the Dask cluster during the run ({why or 'connection lost'}); "
                    f"{len(outcomes)} of {len(idx)} tasks had finished"
                ) from None
            fut.release()  # the worker may drop the result now
            for key in task_needs.pop(fut.key, ()):
                uses[key] -= 1
                if uses[key] == 0:
                    made.pop(key).release()  # no task needs it any more
            record(out)
    except BaseException:
        if getattr(client, "status", None) == "running":
            with contextlib.suppress(Exception):
                client.cancel([*pending.futures, *made.values()])
        raise
