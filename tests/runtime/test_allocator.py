"""The C allocator's settings of a ``bench-sim`` process (:mod:`bench_sim.runtime.allocator`): set
only in such a process, the user's ``MALLOC_ARENA_MAX`` left alone, the mmap threshold of
:func:`large_blocks_mapped` restored after its block (also on an error)."""

from __future__ import annotations

import pytest

from bench_sim.runtime import allocator


class _FakeLibc:
    def __init__(self) -> None:
        self.calls: list[tuple[int, int]] = []

    def mallopt(self, param: int, value: int) -> int:
        self.calls.append((param, value))
        return 1

    def malloc_trim(self, pad: int) -> int:
        self.calls.append((0, pad))
        return 1


@pytest.fixture
def libc(monkeypatch) -> _FakeLibc:
    fake = _FakeLibc()
    monkeypatch.setattr(allocator, "_glibc", lambda: fake)
    monkeypatch.setattr(allocator, "_TUNED", False)
    return fake


def test_one_arena_leaves_the_users_setting_alone(libc, monkeypatch):
    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    assert not allocator.one_arena() and libc.calls == []
    monkeypatch.delenv("MALLOC_ARENA_MAX")
    assert allocator.one_arena() and libc.calls == [(allocator.M_ARENA_MAX, 1)]


def test_large_blocks_mapped_changes_nothing_outside_bench_sim(libc):
    with allocator.large_blocks_mapped():
        pass
    assert libc.calls == []


def test_large_blocks_mapped_restores_the_threshold_after_an_error(libc, monkeypatch):
    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    allocator.one_arena()
    libc.calls.clear()
    with pytest.raises(KeyError), allocator.large_blocks_mapped(2**20):
        raise KeyError("inside")
    assert libc.calls == [(allocator.M_MMAP_THRESHOLD, 2**20),
                          (allocator.M_MMAP_THRESHOLD, allocator.DYNAMIC_MMAP_THRESHOLD_MAX)]


def test_give_back_on_this_machine_raises_nothing():
    assert isinstance(allocator.give_back(), bool)
