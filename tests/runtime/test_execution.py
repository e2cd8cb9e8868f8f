"""The execution layer: per-task streams, failure isolation, same results in and out of Dask."""

from __future__ import annotations

import gc
import itertools
import os

import numpy as np
import pytest

from bench_sim.errors import BenchSimError
from bench_sim.runtime.execution import (
    Shared,
    open_client,
    release_client,
    run_tasks,
    task_generator,
    task_seed_sequence,
    worker_cache,
)


def _draw(arg: tuple[int, int]) -> list[float]:
    """A task: four normal draws from its own stream; task 3 fails."""
    seed, i = arg
    if i == 3:
        raise BenchSimError("point 3: refused\nsecond line is dropped")
    return task_generator(seed, i).normal(size=4).tolist()


@pytest.mark.parametrize("index", [0, 1, 7, 31])
def test_task_stream_is_the_spawned_child(index: int) -> None:
    spawned = np.random.SeedSequence(1234).spawn(32)[index]
    assert task_seed_sequence(1234, index).generate_state(4).tolist() == spawned.generate_state(4).tolist()


def test_streams_differ_between_tasks() -> None:
    a = task_generator(5, 0).normal(size=1000)
    b = task_generator(5, 1).normal(size=1000)
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.15


def test_local_cluster_equals_in_process_and_isolates_failures() -> None:
    args = [(11, i) for i in range(6)]
    with open_client(workers=0) as client:
        serial = run_tasks(_draw, args, client=client)
    seen: list[int] = []
    with open_client(workers=2) as client:
        parallel = run_tasks(_draw, args, client=client, on_result=lambda o: seen.append(o.index))
    assert sorted(seen) == list(range(6))
    for s, p in zip(serial, parallel, strict=True):
        assert s.index == p.index
        assert s.value == p.value
        assert s.error == p.error
    assert not parallel[3].ok
    assert parallel[3].error == "BenchSimError: point 3: refused"
    assert all(o.ok for i, o in enumerate(parallel) if i != 3)
    assert {o.worker for o in parallel} != {"local"}


def test_resumed_indices_keep_their_streams() -> None:
    full = run_tasks(_draw, [(2, i) for i in range(5)], client=None)
    part = run_tasks(_draw, [(2, 4), (2, 1)], client=None, indices=[4, 1])
    assert [o.index for o in part] == [4, 1]
    assert part[0].value == full[4].value and part[1].value == full[1].value


def test_values_dropped_after_on_result_when_asked() -> None:
    seen: dict[int, list[float]] = {}
    outs = run_tasks(
        _draw, [(2, 0), (2, 1)], client=None, keep_values=False,
        on_result=lambda o: seen.update({o.index: o.value}),
    )
    assert [o.index for o in outs] == [0, 1] and all(o.ok and o.value is None for o in outs)
    assert seen[1] == task_generator(2, 1).normal(size=4).tolist()


def test_worker_cache_builds_once() -> None:
    calls: list[int] = []
    key = "test-worker-cache-builds-once"
    assert worker_cache(key, lambda: calls.append(1) or "made") == "made"
    assert worker_cache(key, lambda: calls.append(1) or "again") == "made"
    assert calls == [1]


def test_unreachable_scheduler_is_one_line() -> None:
    with pytest.raises(BenchSimError, match=r"^--scheduler = 'tcp://127.0.0.1:9': cannot reach"):
        with open_client(scheduler="tcp://127.0.0.1:9", connect_timeout_s=2):
            pass


def _offset(arg: int) -> int:
    """A shared input: counts how often it is made (in this process)."""
    _MADE.append(arg)
    if arg < 0:
        raise BenchSimError("negative offset refused")
    return 1000 * arg


_MADE: list[int] = []


def _add(arg: int, *inputs: int) -> int:
    """A task that adds its shared inputs to its argument."""
    return arg + sum(inputs)


def _shared_for(args: list[int]) -> list[tuple[Shared, ...]]:
    """Even arguments share offset 0, odd ones offset 1; argument 5's offset fails."""
    off = [-2 if a == 5 else a % 2 for a in args]
    return [(Shared(f"offset {o}", _offset, o),) for o in off]


def test_shared_inputs_made_once_per_key_in_and_out_of_dask() -> None:
    args = [0, 1, 2, 3, 4, 5]
    _MADE.clear()
    here = run_tasks(_add, args, client=None, shared=_shared_for(args))
    assert sorted(_MADE) == [-2, 0, 1]  # one per key, in this process
    assert [o.value for o in here[:5]] == [0, 1001, 2, 1003, 4]
    assert here[5].error == "BenchSimError: negative offset refused"  # its input failed: it fails
    with open_client(workers=2) as client:
        there = run_tasks(_add, args, client=client, shared=_shared_for(args))
    assert [(o.value, o.error) for o in there] == [(o.value, o.error) for o in here]
    assert all(o.ok for o in there[:5])


@pytest.mark.slow
def test_a_released_cluster_closes_on_its_own_thread_and_is_closed_when_the_block_ends(tmp_path) -> None:
    import dask.base
    import xarray as xr

    with open_client(workers=1) as client:
        assert run_tasks(_draw, [(5, 0)], client=client)[0].ok
        assert dask.base.get_scheduler() is not None  # the open client is Dask's default scheduler
        cluster = client.cluster
        release_client(client)
        # the client is closed at once: what the caller writes next is Dask's and xarray's own
        # business again (a netCDF write would otherwise take the closing cluster's lock)
        assert client.status == "closed" and dask.base.get_scheduler() is None
        xr.Dataset({"x": ("i", np.arange(3.0))}).to_netcdf(tmp_path / "written_while_closing.nc")
        release_client(client)  # a second call changes nothing
        release_client(None)  # nor one for in-process runs
    assert cluster.status.name == "closed"
    with xr.open_dataset(tmp_path / "written_while_closing.nc") as ds:
        assert ds["x"].values.tolist() == [0.0, 1.0, 2.0]


def test_meanwhile_runs_here_once_the_tasks_are_on_the_cluster_and_never_in_process() -> None:
    import threading

    calls: list[str] = []
    seen: list[int] = []
    run_tasks(_draw, [(5, 0)], client=None, meanwhile=lambda: calls.append("in-process"))
    assert calls == []
    with open_client(workers=1) as client:
        def meanwhile() -> None:  # before any outcome is handed over, in the caller's thread
            calls.append(threading.current_thread().name)
            assert seen == []

        out = run_tasks(_draw, [(5, 0), (5, 1)], client=client, on_result=lambda o: seen.append(o.index),
                        meanwhile=meanwhile)
    assert calls == [threading.current_thread().name]
    assert [o.ok for o in out] == [True, True] and sorted(seen) == [0, 1]


def _profiles(dask_worker) -> bool:
    """Whether a worker samples its tasks' stacks for the dashboard (Dask's statistical profiler)."""
    return "profile" in dask_worker.periodic_callbacks


@pytest.mark.slow
@pytest.mark.parametrize("user_value", [None, "1048576"])
def test_local_workers_start_without_dasks_trim_threshold(monkeypatch, user_value: str | None) -> None:
    """Dask's nannies start a worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (glibc's dynamic mmap
    threshold off: each large array of a point is page-faulted again) and a profiler thread; a
    local cluster of bench_sim's starts its workers without either, and keeps a value of the
    variable the user set."""
    if user_value is None:
        monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    else:
        monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", user_value)
    with open_client(workers=1) as client:
        seen = client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_")
        profiling = client.run(_profiles)
        frozen = client.run(gc.get_freeze_count)  # bench-sim's own process (runtime.collector)
    assert list(seen.values()) == [user_value]
    assert all(n > 0 for n in frozen.values())
    assert list(profiling.values()) == [False]  # nor the dashboard's statistical profiler
    assert os.environ.get("MALLOC_TRIM_THRESHOLD_") == user_value  # nor set in this process


def _started(_arg: int, _shared: int) -> int:
    """A task: the how-manieth task of its worker process it is (0, 1, ...)."""
    return next(worker_cache("started", itertools.count))


@pytest.mark.slow
def test_tasks_waiting_for_a_shared_input_start_in_the_order_given() -> None:
    """Dask starts the tasks whose inputs became ready together in an order of its own; a run's
    tasks start in its order (a dataset's first, often longest, sample is not left for last)."""
    with open_client(workers=1) as client:
        out = run_tasks(_started, list(range(8)), client=client, shared=[(Shared("in", abs, 1),)] * 8)
    assert [o.value for o in out] == list(range(8))
