"""Resource checks: the memory and disk a run needs against what is available.

Every command estimates, before it computes anything, the peak memory of its run and the size
of the files it writes (:class:`ResourceEstimate`, one named term per large array; the
per-command estimates are :mod:`bench_sim.workflows.estimates`), and :func:`check_resources`
refuses a run that cannot fit with one line giving the estimate, its largest term, what is
available and what to lower.

Available memory is the smallest of ``MemAvailable`` (``/proc/meminfo``), the cgroup limit less
its usage (containers, batch jobs) and ``RLIMIT_AS`` less the process's size; available disk is
the free space of the file system that receives the output (:func:`bench_sim.io.check_free_space`;
the temporary folder of an output set lies beside it, so the new set must fit next to the old
one). Commands that run many tasks count the tasks that run at once on this machine
(:func:`local_concurrency`).
"""

from __future__ import annotations

import os
import resource
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from bench_sim.errors import BenchSimError
from bench_sim.io import check_free_space, format_bytes
from bench_sim.runtime.execution import default_workers

__all__ = [
    "ResourceEstimate",
    "ResourceError",
    "available_memory_bytes",
    "check_resources",
    "local_concurrency",
    "BASE_PROCESS_BYTES",
    "BASE_MITSUBA_BYTES",
    "MiB",
]

MiB = 1 << 20
#: The interpreter with numpy, pydantic, matplotlib, xarray and the I/O libraries loaded (160 MiB
#: measured) [bytes].
BASE_PROCESS_BYTES = 200 * MiB
#: Extra for Mitsuba / Dr.Jit with its LLVM backend, the scene and the compiled kernels [bytes].
BASE_MITSUBA_BYTES = 150 * MiB


class ResourceError(BenchSimError):
    """A run that would not fit in the memory or on the disk available (one line)."""


@dataclass(frozen=True)
class ResourceEstimate:
    """What a run needs.

    Attributes
    ----------
    command
        The command or run, for messages (``"render"``).
    memory_bytes
        Named terms of the peak memory [bytes] (they add up).
    disk_bytes
        Named terms of the output size [bytes].
    hint
        What to lower, naming the keys or options and their values (``"lower --frames (8)"``).
    """

    command: str
    memory_bytes: Mapping[str, int] = field(default_factory=dict)
    disk_bytes: Mapping[str, int] = field(default_factory=dict)
    hint: str = ""

    @property
    def memory_total(self) -> int:
        return int(sum(self.memory_bytes.values()))

    @property
    def disk_total(self) -> int:
        return int(sum(self.disk_bytes.values()))

    def largest(self, which: str) -> tuple[str, int]:
        """The largest memory or disk term, ``(name, bytes)``."""
        terms = self.memory_bytes if which == "memory" else self.disk_bytes
        return max(terms.items(), key=lambda kv: kv[1]) if terms else ("-", 0)


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_available() -> int | None:
    for limit, usage in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        lim = _read_int(limit)
        if lim is not None and lim < 1 << 60:
            return max(lim - (_read_int(usage) or 0), 0)
    return None


def _rlimit_available() -> int | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    size = 0
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                size = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return max(soft - size, 0)


def available_memory_bytes() -> tuple[int, str] | None:
    """Memory this process can still use [bytes] and where the bound comes from, or ``None``
    where nothing can be read (then no memory check is made)."""
    found = [
        (v, name)
        for v, name in (
            (_meminfo_available(), "MemAvailable"),
            (_cgroup_available(), "cgroup limit"),
            (_rlimit_available(), "ulimit -v"),
        )
        if v is not None
    ]
    return min(found) if found else None


def check_resources(
    est: ResourceEstimate, out: str | os.PathLike[str] | None = None, what: str = "--out"
) -> None:
    """Refuse a run that cannot fit: one line with the estimate, its largest term, what is
    available and :attr:`ResourceEstimate.hint`. ``out``: where the outputs go (the disk check,
    :func:`bench_sim.io.check_free_space`)."""
    mem = available_memory_bytes()
    if mem is not None and est.memory_total > mem[0]:
        name, size = est.largest("memory")
        raise ResourceError(
            f"not enough memory: {est.command} needs about {format_bytes(est.memory_total)} "
            f"(largest: {name}, {format_bytes(size)}) but {format_bytes(mem[0])} is available "
            f"({mem[1]}); {est.hint}"
        )
    if out is not None and est.disk_bytes:
        name, size = est.largest("disk")
        detail = f"{est.command}'s output, largest: {name}, {format_bytes(size)}; or {est.hint}"
        check_free_space(out, est.disk_total, what, detail)


def local_concurrency(workers: int | None, scheduler: str | None) -> int:
    """Tasks that run at once on this machine: ``workers`` local worker processes (default:
    the usable cores; ``0``: in this process, one at a time), or ``0`` with a scheduler (the
    tasks run on the cluster's machines, whose memory this machine cannot see)."""
    if scheduler is not None:
        return 0
    if workers is None:
        return default_workers()
    return max(int(workers), 1)


