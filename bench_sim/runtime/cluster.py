"""Reaching a Dask cluster safely: the address checked, the scheduler recognised, workers waited
for, a local cluster that stops quietly.

Each way a cluster can fail is one line before anything is written, never a hang or a
misleading message:

- :func:`check_scheduler_address`: the syntax of ``--scheduler`` (``tcp://HOST:PORT``, also
  ``tls://``, ``ws://``, ``wss://`` or a bare ``HOST:PORT``); an ``http://`` address (the
  dashboard's) is refused with the hint that the scheduler listens on ``tcp://``, port 8786 by
  default.
- :func:`probe_scheduler`: a TCP connection and the first message of Dask's handshake (a Dask
  scheduler sends it as soon as it accepts a connection: an 8-byte length, frames, a msgpack
  map naming ``pickle-protocol``), each within ``timeout_s``. Nothing listening, something that
  accepts and never answers, or something that answers otherwise (an HTTP server, another
  service) is refused, naming what was found.
- :func:`wait_for_workers`: a connected scheduler with no worker is waited for a grace period
  (one warning line), then refused with the count.
- :func:`quiet_local_cluster`: a ``LocalCluster`` whose worker processes never take Ctrl-C (the
  terminal sends it to the whole process group; the client process shuts them down itself), so
  Ctrl-C prints one line, not a worker's traceback; a Ctrl-C while the cluster starts is held
  and delivered when the start ends (the cluster then closed again), never lost.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import logging
import os
import re
import signal
import socket
import struct
import threading
import time
import warnings
from collections.abc import Iterator
from typing import Any

from bench_sim.errors import BenchSimError, ClusterError
from bench_sim.io.interrupts import deferred_interrupts
from bench_sim.runtime import collector

__all__ = [
    "SCHEMES",
    "check_scheduler_address",
    "probe_scheduler",
    "wait_for_workers",
    "quiet_local_cluster",
    "quiet_dask_logs",
    "close_in_background",
]

#: Address schemes of a Dask scheduler bench_sim accepts (``HOST:PORT`` alone means ``tcp://``)
SCHEMES = ("tcp", "tls", "ws", "wss")
_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:.]+\]|[^\s/:\[\]]+):(?P<port>\d+)/?$")
#: Dask's loggers in the client process (silenced by :func:`quiet_dask_logs`)
_DASK_LOGGERS = ("distributed", "distributed.client", "distributed.core", "distributed.comm",
                 "distributed.nanny", "distributed.worker", "distributed.scheduler", "distributed.batched",
                 "distributed.utils", "tornado", "asyncio")
#: Longest first message of a scheduler's handshake that is believed [bytes]
_MAX_HANDSHAKE = 1 << 20


def check_scheduler_address(address: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a scheduler address, or one line saying what is allowed."""
    text = address.strip()
    m = _ADDRESS.match(text)
    scheme = (m.group("scheme") if m else None) or "tcp"
    if text.lower().startswith(("http://", "https://")):
        raise BenchSimError(
            f"--scheduler = {address!r}: an HTTP address (a dashboard?); a Dask scheduler listens on "
            "tcp://HOST:PORT (port 8786 by default)"
        )
    if m is None or scheme not in SCHEMES or not 0 < int(m.group("port")) < 65536:
        raise BenchSimError(
            f"--scheduler = {address!r}: not a scheduler address; expected tcp://HOST:PORT "
            f"(schemes: {', '.join(SCHEMES)}; port 1..65535)"
        )
    return scheme, m.group("host").strip("[]"), int(m.group("port"))


def _recv_exactly(sock: socket.socket, n: int, deadline: float) -> bytes:
    data = b""
    while len(data) < n:
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionResetError("closed the connection")
        data += chunk
    return data


def probe_scheduler(address: str, timeout_s: float = 10.0) -> None:
    """Check that a Dask scheduler answers at ``address`` within ``timeout_s`` [s] (see the
    module docstring); one :class:`~bench_sim.errors.BenchSimError` line otherwise. Only
    ``tcp://`` addresses are probed (the others are left to the client's own timeout)."""
    scheme, host, port = check_scheduler_address(address)
    if scheme != "tcp":
        return
    where = f"--scheduler = {address!r}"
    deadline = time.monotonic() + timeout_s
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except TimeoutError:
        raise BenchSimError(f"{where}: cannot reach a Dask scheduler there (no answer to a connection "
                            f"within {timeout_s:g} s)") from None
    except OSError as exc:
        raise BenchSimError(f"{where}: cannot reach a Dask scheduler there ({exc.strerror or exc}; start "
                            "one with 'dask scheduler')") from None
    with sock:
        try:
            head = _recv_exactly(sock, 8, deadline)
            if head.startswith(b"HTTP") or head[:1] in (b"<", b"{"):
                raise BenchSimError(f"{where}: an HTTP or text service answered (the dashboard?), not a "
                                    "Dask scheduler; its address is tcp://HOST:PORT, port 8786 by default")
            size = struct.unpack("<Q", head)[0]
            body = _recv_exactly(sock, size, deadline) if 16 <= size <= _MAX_HANDSHAKE else b""
        except TimeoutError:
            raise BenchSimError(
                f"{where}: something accepted the connection but sent no Dask handshake within "
                f"{timeout_s:g} s: not a Dask scheduler"
            ) from None
        except OSError as exc:
            raise BenchSimError(f"{where}: the connection failed during the handshake "
                                f"({exc.strerror or exc}): not a Dask scheduler") from None
    if b"pickle-protocol" not in body:
        raise BenchSimError(f"{where}: something answered with {head[:8]!r}..., not a Dask scheduler's "
                            "handshake")


def wait_for_workers(client: Any, address: str, grace_s: float = 10.0, timeout_s: float = 120.0) -> int:
    """Wait until the scheduler has at least one worker; the number of workers.

    After ``grace_s`` [s] without one, one warning line says so (and how to start one); after
    ``timeout_s`` [s], :class:`~bench_sim.errors.ClusterError` (nothing has been written yet).
    """
    t0 = time.monotonic()
    warned = False
    while True:
        n = len(client.scheduler_info(n_workers=-1).get("workers", {}))
        if n:
            return n
        waited = time.monotonic() - t0
        if waited >= timeout_s:
            raise ClusterError(
                f"--scheduler = {address!r}: 0 workers connected after {timeout_s:g} s; start some with "
                f"'dask worker {address}' (BENCH_SIM_WORKER_WAIT_S sets the wait)"
            )
        if waited >= grace_s and not warned:
            warned = True
            warnings.warn(
                f"bench_sim: --scheduler = {address!r}: 0 workers connected after {grace_s:g} s; waiting "
                f"up to {timeout_s:g} s (start one with 'dask worker {address}')",
                RuntimeWarning,
                stacklevel=2,
            )
        time.sleep(0.25)


@contextlib.contextmanager
def _sigint_blocked_for_new_workers() -> Iterator[None]:
    """SIGINT blocked in this thread during the block: the threads started in it (the cluster's
    event loop, which starts the worker processes) and so the worker processes inherit the
    blocked signal and never take Ctrl-C (the client process stops them). In this process a
    SIGINT that comes meanwhile stays pending, or goes to another thread, and is not lost: the
    Python handler (:func:`~bench_sim.io.interrupts.deferred_interrupts`' while the cluster
    starts) runs once the block ends."""
    from multiprocessing import resource_tracker

    # started here first: started from the cluster's event loop it would unblock SIGINT in that
    # thread afterwards (its ensure_running blocks, spawns, then unblocks), and so in the workers
    resource_tracker.ensure_running()
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    except (AttributeError, OSError):  # pragma: no cover - a platform without signal masks
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _own_process_group() -> None:
    """Move this worker process into a process group of its own: Ctrl-C at the terminal (sent to
    the foreground group) then reaches only the client process, which stops the workers itself.
    Without this, a worker rendering at that moment takes the signal too (Mitsuba's render
    installs its own SIGINT handler) and prints its own lines."""
    with contextlib.suppress(OSError, AttributeError):
        os.setpgid(0, 0)


def _prepare_worker() -> None:
    """Run in each worker process of a local cluster as it starts: its own process group
    (:func:`_own_process_group`), ``bench-sim``'s own garbage collector settings
    (:func:`bench_sim.runtime.collector.own`) and a quick exit. At its exit the interpreter's last garbage
    collection walks every object the run's imports made (Mitsuba, xarray, numba: ~1 s per
    worker, which the cluster's close waits for); ``gc.freeze`` at exit leaves those out. The
    worker's tasks and their files are closed by then, and its memory goes back with the process.
    Nothing is imported here on a thread of its own meanwhile (see :mod:`bench_sim.runtime.preload`
    for why): a worker imports what its tasks need as it runs them."""
    _own_process_group()
    collector.own()  # its objects so far settled; its first task settles again (collector.settle_once)
    atexit.register(gc.freeze)


#: Dask settings a local cluster of bench_sim's starts its workers with (:func:`_worker_settings`)
WORKER_SETTINGS: dict[str, Any] = {
    # in the nannies' environment for a new worker process: nothing (a value set by the user is kept)
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.worker.profile.enabled": False,
}


@contextlib.contextmanager
def _worker_settings() -> Iterator[None]:
    """Within the block, new workers start with :data:`WORKER_SETTINGS`:

    - **Without Dask's** ``MALLOC_TRIM_THRESHOLD_`` (``distributed.nanny.pre-spawn-environ``; a
      value the user set in the environment is kept). Any value of that variable turns off
      glibc's dynamic mmap threshold: every block of 128 KiB or more is then mapped on its own
      and unmapped when freed, so each array a point makes is paid again in page faults (a fault
      per 4 KiB page). A sweep point's warm pass took 0.76 s with it and 0.40 s without (180,000
      against 10,000 page faults), the time of a 6-point sweep's two workers in the kernel 1.5 s
      each against 0.5 s; their peak resident memory grew by 6-15 % (``docs/performance.md``).
      Dask sets it to give memory back to the system sooner, which a worker that lives for one
      run does not need.
    - **Without the statistical profiler** (``distributed.worker.profile.enabled``): a thread of
      each worker walks the task's stack every 10 ms for the dashboard's profile page, which
      bench_sim never shows; a 6-point ``--quick`` sweep took about 0.2 s less wall time and 0.3 s
      less CPU without it.
    """
    import dask

    with dask.config.set(WORKER_SETTINGS):
        yield


@contextlib.contextmanager
def quiet_local_cluster(n_workers: int) -> Iterator[Any]:
    """A ``LocalCluster`` of ``n_workers`` one-thread processes and its client, closed in order
    (client, then cluster: no unclosed socket); its workers ignore Ctrl-C (see the module
    docstring) and log only errors."""
    from distributed import Client, LocalCluster

    with warnings.catch_warnings():
        # the scheduler's HTTP endpoints fall back to a free port when 8787 is taken (another
        # cluster on the machine): nothing the user needs to act on
        warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
        cluster: Any = None
        client: Any = None
        try:
            # Ctrl-C and SIGTERM held while the cluster starts (5-30 s under load) and delivered
            # when the start ends: here, where the cluster is closed again before they go on
            with deferred_interrupts():
                with _sigint_blocked_for_new_workers(), _worker_settings():
                    cluster = LocalCluster(
                        n_workers=n_workers,
                        threads_per_worker=1,
                        processes=True,
                        # its HTTP endpoints on a free loopback port: the default 8787, when taken by
                        # another cluster, leaks a socket in the retry (an "unclosed socket" warning)
                        dashboard_address="127.0.0.1:0",
                        silence_logs=logging.CRITICAL,
                        # one core per worker: the chain's own thread pools use one thread in a worker
                        env={"BENCH_SIM_THREADS": "1", "OMP_NUM_THREADS": "1"},
                    )
                client = Client(cluster)
                client.run(_prepare_worker)  # in every worker of the cluster
        except BaseException:
            if cluster is not None:
                _close_quietly(client, cluster)
            raise
    try:
        yield client
    finally:
        closer = _CLOSERS.pop(id(client), None)
        if closer is None:
            _close_quietly(client, cluster)
        else:  # started by close_in_background: wait for it
            closer.join()


#: background closes started by :func:`close_in_background`, by ``id`` of their client
_CLOSERS: dict[int, threading.Thread] = {}


def close_in_background(client: Any) -> None:
    """Close the client of a :func:`quiet_local_cluster` now, then start closing its cluster on
    a thread of its own: the caller's last writes run while the workers stop (a close waits for
    the worker processes to exit). The ``with`` block's end waits for the close. Nothing for any
    other client (a ``--scheduler`` cluster's is closed at the block's end).

    The client is closed here, in the caller's thread, before its writes: while a client is
    open it is Dask's default scheduler, and xarray then writes a file under a lock of the
    cluster's (``dask.distributed.Lock``): a write racing the close fails, and leaves xarray's
    own HDF5 lock held (the next netCDF write of the process waits for ever). The thread only
    closes the cluster, and sets no process-wide state (a ``warnings.catch_warnings`` there
    would race the caller's filters): the caller's ``open_client`` block keeps Dask's logs quiet
    until the close is joined."""
    cluster = getattr(client, "cluster", None)
    if client is None or cluster is None or id(client) in _CLOSERS:
        return
    _close_quietly(client, None)
    thread = threading.Thread(target=_close_cluster, args=(cluster,), name="bench_sim-close", daemon=True)
    _CLOSERS[id(client)] = thread
    thread.start()


def _close_cluster(cluster: Any) -> None:
    """Close a local cluster, ignoring its errors (on :func:`close_in_background`'s thread)."""
    with contextlib.suppress(Exception):
        cluster.close(timeout=10)


@contextlib.contextmanager
def quiet_dask_logs() -> Iterator[None]:
    """Dask's own log lines silenced in this process for the block: a lost scheduler, a closing
    worker or a reconnection attempt is reported by bench_sim in one line, not by Dask's logger
    with its traceback (``BENCH_SIM_DEBUG=1`` keeps them). The levels are restored when the block
    ends normally; after an exception they stay quiet (the run is over)."""
    if os.environ.get("BENCH_SIM_DEBUG") == "1":
        yield
        return
    import distributed  # noqa: F401 - its import configures these loggers: quieted after it

    loggers = [logging.getLogger(n) for n in _DASK_LOGGERS]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    yield  # an exception (a lost scheduler, Ctrl-C) leaves them quiet: the client's background
    # tasks (reconnection attempts) log their end after the block, while the process exits
    for lg, lv in zip(loggers, levels, strict=True):
        lg.setLevel(lv)


def _close_quietly(client: Any, cluster: Any) -> None:
    """Close the client, then the cluster (if any), with the shutdown's own log lines silenced."""
    with quiet_dask_logs(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=10)
        if cluster is not None:
            _close_cluster(cluster)
