"""In-process parallelism for the cores of one machine, and the random streams that keep its
results independent of the number of threads.

Work is split into fixed pieces (chunks of frames, bands of texel columns) whose results do not
depend on how many threads run them: every piece computes the same numbers alone or beside
others, and every random piece draws from its own generator, spawned from a
``numpy.random.SeedSequence`` by the piece's index (:func:`chunk_generator`). So a run gives
bit-identical output with 1 or 16 threads.

``BENCH_SIM_THREADS`` sets the number of threads (default: the usable cores; the Dask workers of
:mod:`bench_sim.runtime.execution` set it to 1, one core per worker). Scale-out over machines
is Dask's job, not this module's.

Pool
    One process-wide :class:`concurrent.futures.ThreadPoolExecutor` per thread count runs *leaf*
    tasks: tasks that never wait for other tasks of the pool. :func:`parallel_map` called from
    inside a pool thread runs its pieces in that thread, so nesting cannot deadlock.

Lane
    :class:`Lane`: one more thread that runs a workflow's independent *steps* in order beside
    the caller's (a step may use the pool: it is no pool thread). With one thread the steps run
    in the caller when their results are asked for: the same numbers either way.
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = [
    "thread_count",
    "pool",
    "parallel_map",
    "start",
    "ordered_imap",
    "prefetch",
    "seed_sequence",
    "child_sequence",
    "chunk_generator",
    "Lane",
]

T = TypeVar("T")
R = TypeVar("R")

_pools: dict[int, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()
_in_pool = threading.local()


def thread_count() -> int:
    """Threads for in-process work: ``BENCH_SIM_THREADS`` if set, else the usable cores."""
    env = os.environ.get("BENCH_SIM_THREADS", "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            n = 0
        if n < 1:
            raise BenchSimError(f"BENCH_SIM_THREADS = {env!r}: must be an integer >= 1")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _mark_pool_thread() -> None:
    _in_pool.active = True


def pool(threads: int | None = None) -> ThreadPoolExecutor | None:
    """The process-wide pool of ``threads`` (default :func:`thread_count`) threads; ``None``
    for one thread or when called from a pool thread (run inline)."""
    n = thread_count() if threads is None else int(threads)
    if n <= 1 or getattr(_in_pool, "active", False):
        return None
    with _pools_lock:
        ex = _pools.get(n)
        if ex is None:
            ex = ThreadPoolExecutor(n, thread_name_prefix="bench_sim", initializer=_mark_pool_thread)
            _pools[n] = ex
        return ex


def parallel_map(func: Callable[[T], R], items: Sequence[T], threads: int | None = None) -> list[R]:
    """``[func(x) for x in items]`` on the pool, results in the order of ``items``."""
    ex = pool(threads)
    if ex is None or len(items) <= 1:
        return [func(x) for x in items]
    return [f.result() for f in [ex.submit(func, x) for x in items]]


def start(jobs: Sequence[Callable[[], R]], threads: int | None = None) -> Callable[[], list[R]]:
    """Start ``jobs`` on the pool and return a function that waits for them and returns their
    results in order (with one thread they run here, now). The caller works on meanwhile."""
    ex = pool(threads)
    if ex is None:
        done = [job() for job in jobs]
        return lambda: done
    futures = [ex.submit(job) for job in jobs]
    return lambda: [f.result() for f in futures]


def ordered_imap(
    func: Callable[[T], R], items: Iterable[T], ahead: int | None = None, threads: int | None = None
) -> Iterator[R]:
    """``func`` over ``items`` on the pool, yielded in order, with at most ``ahead`` (default:
    twice the threads) results computed before the consumer takes them. ``items`` is consumed
    in order, by the caller's thread, as results are taken (it may be a generator)."""
    ex = pool(threads)
    if ex is None:
        for x in items:
            yield func(x)
        return
    n = thread_count() if threads is None else int(threads)
    depth = max(1, 2 * n if ahead is None else int(ahead))
    pending: list[Future[R]] = []
    it = iter(items)
    try:
        for x in it:
            pending.append(ex.submit(func, x))
            if len(pending) >= depth:
                yield pending.pop(0).result()
        while pending:
            yield pending.pop(0).result()
    finally:
        for f in pending:
            f.cancel()


def prefetch(items: Iterable[T], depth: int = 1, threads: int | None = None) -> Iterator[T]:
    """Iterate ``items`` in a background thread, up to ``depth`` items ahead of the one the
    consumer holds (a producer that itself uses the pool, e.g. rendering, overlaps with the
    consumer's work): at most ``depth + 1`` items exist at once, the consumer's included, so a
    consumer that drops each item before it asks for the next holds ``depth + 1`` (not
    ``depth + 2``, as a bounded queue with the producer blocked on it would). With one thread,
    ``items`` is iterated in the caller's thread. Errors reach the consumer."""
    n = thread_count() if threads is None else int(threads)
    if n <= 1:
        yield from items
        return
    q: queue.Queue[tuple[str, object]] = queue.Queue()
    #: items the producer may make before the consumer takes one
    slots = threading.Semaphore(max(1, int(depth)))
    stop = threading.Event()
    end = object()

    def produce() -> None:
        try:
            it = iter(items)
            while True:
                while not slots.acquire(timeout=0.1):
                    if stop.is_set():
                        return
                if stop.is_set():
                    return
                x = next(it, end)
                if x is end:
                    break
                q.put(("item", x))
                del x  # not held while the next slot is awaited
            q.put(("end", None))
        except BaseException as exc:  # handed to the consumer
            q.put(("error", exc))

    worker = threading.Thread(target=produce, name="bench_sim-prefetch", daemon=True)
    worker.start()
    try:
        while True:
            kind, value = q.get()
            if kind == "end":
                return
            if kind == "error":
                raise value  # type: ignore[misc]
            slots.release()  # taken: the producer may make the next one meanwhile
            yield value  # type: ignore[misc]
            del value  # not held while the next is awaited
    finally:
        stop.set()
        worker.join()


class Lane:
    """Steps of a workflow run in order on one background thread beside the caller's
    (``threads`` > 1, default :func:`thread_count`), or deferred in the caller with one thread.

    :meth:`submit` returns a function that waits for the step's result (and raises its error).
    Used as a context manager: on a normal exit it waits for every step (the first error is
    raised); on an error it drops the steps not started and waits for the running one, so no
    step outlives the block (nor writes into a folder the caller removes).
    """

    def __init__(self, threads: int | None = None) -> None:
        n = thread_count() if threads is None else int(threads)
        self._ex = ThreadPoolExecutor(1, thread_name_prefix="bench_sim-lane") if n > 1 else None
        self._futures: list[Future[object]] = []
        self._deferred: list[Callable[[], object]] = []

    @property
    def parallel(self) -> bool:
        """Whether the steps run on their own thread."""
        return self._ex is not None

    def submit(self, step: Callable[[], R]) -> Callable[[], R]:
        """Queue ``step``; returns the wait for its result."""
        if self._ex is None:
            done: list[R] = []

            def run() -> R:
                if not done:
                    done.append(step())
                return done[0]

            self._deferred.append(run)
            return run
        fut = self._ex.submit(step)
        self._futures.append(fut)  # type: ignore[arg-type]
        return fut.result

    def join(self) -> None:
        """Wait for every step queued (run the deferred ones); raise the first error."""
        for run in self._deferred:
            run()
        for f in self._futures:
            f.result()

    def cancel(self) -> None:
        """Drop the steps not started, wait for the running one; errors are dropped."""
        self._deferred.clear()
        for f in self._futures:
            f.cancel()
        if self._ex is not None:
            self._ex.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> Lane:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is not None:
            self.cancel()
            return
        try:
            self.join()
        except BaseException:
            self.cancel()
            raise
        if self._ex is not None:
            self._ex.shutdown(wait=True)


def seed_sequence(seed: int | np.random.SeedSequence | np.random.Generator) -> np.random.SeedSequence:
    """The root ``SeedSequence`` of a piece of work.

    An integer seeds it; a ``SeedSequence`` is used as is; a ``Generator`` gives 128 bits of
    entropy drawn from it (the generator moves on by one draw), so a run handed a generator
    stays reproducible from that generator's seed.
    """
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, np.random.Generator):
        return np.random.SeedSequence(seed.integers(0, 2**32, size=4, dtype=np.uint64).tolist())
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or int(seed) < 0:
        raise BenchSimError(f"seed = {seed!r}: expected an integer >= 0, a SeedSequence or a Generator")
    return np.random.SeedSequence(int(seed))


def child_sequence(root: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child ``index`` of ``root``: ``root.spawn(n)[index]`` for a root that has spawned nothing
    yet, made directly (without spawning the children before it)."""
    return np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, int(index)))


def chunk_generator(root: np.random.SeedSequence, index: int) -> np.random.Generator:
    """The generator of piece ``index`` under ``root`` (:func:`child_sequence`)."""
    return np.random.default_rng(child_sequence(root, index))
