"""The thread pool's :class:`~bench_sim.runtime.parallel.Lane`: steps in order beside the caller,
or deferred in it with one thread; errors reach the caller; nothing outlives the block."""

from __future__ import annotations

import functools
import threading
import time

import pytest

from bench_sim.runtime.parallel import Lane, parallel_map


@pytest.mark.parametrize("threads", [1, 2])
def test_lane_runs_its_steps_in_order_and_returns_their_results(threads: int) -> None:
    done: list[int] = []

    def step(i: int) -> int:
        done.append(i)
        return i * i

    with Lane(threads) as lane:
        waits = [lane.submit(functools.partial(step, i)) for i in range(5)]
        assert lane.parallel is (threads > 1)
        assert [w() for w in waits] == [0, 1, 4, 9, 16]
    assert done == [0, 1, 2, 3, 4]


def test_one_thread_defers_a_step_until_its_result_is_asked_for() -> None:
    done: list[str] = []
    with Lane(1) as lane:
        first = lane.submit(lambda: done.append("a"))
        lane.submit(lambda: done.append("b"))
        assert done == []  # nothing ran yet: the caller's order
        first()
        assert done == ["a"]
    assert done == ["a", "b"]  # the rest when the block ends


def test_a_steps_result_is_computed_once() -> None:
    calls: list[int] = []

    def step() -> int:
        calls.append(1)
        return len(calls)

    with Lane(1) as lane:
        wait = lane.submit(step)
        assert wait() == wait() == 1
    assert calls == [1]


def test_steps_run_beside_the_caller_on_another_thread() -> None:
    names: list[str] = []
    with Lane(2) as lane:
        lane.submit(lambda: names.append(threading.current_thread().name))()
    assert names and names[0] != threading.current_thread().name


def test_a_step_may_use_the_pool() -> None:
    with Lane(2) as lane:
        assert lane.submit(lambda: parallel_map(lambda x: x + 1, [1, 2, 3], threads=2))() == [2, 3, 4]


@pytest.mark.parametrize("threads", [1, 2])
def test_a_steps_error_reaches_the_caller_at_the_end_of_the_block(threads: int) -> None:
    def fail() -> None:
        raise ValueError("step failed")

    with pytest.raises(ValueError, match="step failed"), Lane(threads) as lane:
        lane.submit(fail)


def test_an_error_in_the_block_drops_the_steps_not_started_and_waits_for_the_running_one() -> None:
    started = threading.Event()
    finished: list[str] = []

    def slow() -> None:
        started.set()
        time.sleep(0.2)
        finished.append("slow")

    with pytest.raises(RuntimeError, match="caller"), Lane(2) as lane:
        lane.submit(slow)
        lane.submit(lambda: finished.append("never"))
        assert started.wait(5)
        raise RuntimeError("caller")
    assert finished == ["slow"]  # the running step ended before the block was left


def test_prefetch_holds_the_consumers_item_and_one_ahead_at_most() -> None:
    """``prefetch(depth=1)`` makes an item only once the consumer has taken the one before: with
    a consumer that drops each item before asking for the next, at most two exist at once (a
    bounded queue with the producer blocked on it held three); the items arrive in order, all
    of them, and the producer still works while the consumer does."""
    import gc
    import weakref

    from bench_sim.runtime.parallel import prefetch

    alive: list[weakref.ref[object]] = []
    most = [0]
    lock = threading.Lock()

    class Item:
        def __init__(self, k: int) -> None:
            self.k = k

    def items():
        for k in range(12):
            with lock:
                gc.collect()
                most[0] = max(most[0], sum(r() is not None for r in alive) + 1)
            item = Item(k)
            alive.append(weakref.ref(item))
            yield item
            del item

    got = []
    for item in prefetch(items(), depth=1, threads=2):
        got.append(item.k)
        time.sleep(0.01)  # the producer runs ahead meanwhile
        del item
    assert got == list(range(12))
    assert most[0] <= 2


def test_prefetch_hands_the_producers_error_to_the_consumer() -> None:
    from bench_sim.runtime.parallel import prefetch

    def items():
        yield 1
        raise RuntimeError("render failed")

    out = []
    with pytest.raises(RuntimeError, match="render failed"):
        for x in prefetch(items(), threads=2):
            out.append(x)
    assert out == [1]
