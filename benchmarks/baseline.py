"""A/B support for the benchmarks: run a command of this checkout and of another git revision.

The other revision (default :data:`BASELINE_REV`, the main branch before the speed work of
this round) is exported once with ``git archive`` into a cache folder and run with this
checkout's virtual environment, its package first on ``PYTHONPATH``, so both sides use the same
libraries. Runs are paired and interleaved (A, B, A, B, ...) so that a change of the machine's
load hits both sides alike; medians and their ratio are printed with the load average.

Both sides run from compiled bytecode (:func:`compiled`: ``compileall`` of the side's package
before its first run): an exported tree has no ``__pycache__``, and where the environment
forbids writing it (``PYTHONDONTWRITEBYTECODE``) every process of that side -- the command and
each Dask worker -- would compile the package's sources again at import (0.25 s of CPU for
``import bench_sim.cli``), a handicap the other side does not carry.

Usage from a benchmark::

    from baseline import add_baseline_args, Side, paired, load_line

    sides = [Side.current(), Side.of_rev(args.baseline)]
    times = paired(sides, lambda side: side.bench_sim("reproduce", "--out", tmp), repeat=3)
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: main before the speed work (issue 26): the "today" of its targets
BASELINE_REV = "63156ef"
_CACHE = Path(tempfile.gettempdir()) / "bench_sim_baselines"


def add_baseline_args(ap: argparse.ArgumentParser) -> None:
    """``--baseline REV`` (default :data:`BASELINE_REV`) and ``--no-baseline``."""
    ap.add_argument("--baseline", default=BASELINE_REV, help="git revision to compare with")
    ap.add_argument("--no-baseline", action="store_true", help="time this checkout only")


def export_tree(rev: str) -> Path:
    """The package tree of ``rev`` (exported once, cached under the temp folder)."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", rev], check=True, capture_output=True,
                         text=True).stdout.strip()
    tree = _CACHE / sha[:12]
    if not (tree / "bench_sim" / "__init__.py").exists():
        tree.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", sha], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return compiled(tree)


def compiled(tree: Path) -> Path:
    """``tree`` with its package's bytecode written and up to date (``python -m compileall``: only
    what is missing or stale is compiled); returns ``tree``."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / "bench_sim")], check=True,
                   stdout=subprocess.DEVNULL)
    return tree


@dataclass(frozen=True)
class Side:
    """One side of an A/B comparison: a name and the ``PYTHONPATH`` that selects its package."""

    name: str
    tree: Path | None

    @classmethod
    def current(cls) -> Side:
        compiled(ROOT)  # the checkout's package (the installed one is this checkout's, editable)
        return cls("this checkout", None)

    @classmethod
    def of_rev(cls, rev: str) -> Side:
        return cls(f"baseline {rev}", export_tree(rev))

    def env(self, **extra: str) -> dict[str, str]:
        env = dict(os.environ, **extra)
        if self.tree is not None:
            env["PYTHONPATH"] = str(self.tree)
        else:
            env.pop("PYTHONPATH", None)
        return env

    def python(self, *args: str, cwd: Path | None = None, **env: str) -> tuple[float, float]:
        """Run ``python -P args`` of this side; wall time and CPU time [s] (the process and its
        children). ``-P``: the working folder is not put first on the import path, so a run from the
        checkout's root cannot import this checkout on the baseline's side."""
        return timed_process([sys.executable, "-P", *args], self.env(**env), cwd=cwd)

    def bench_sim(self, *args: str, cwd: Path | None = None, **env: str) -> tuple[float, float]:
        """Run ``bench-sim args`` of this side (as ``python -m bench_sim``)."""
        return self.python("-m", "bench_sim", *args, cwd=cwd, **env)


def timed_process(argv: Sequence[str], env: dict[str, str], cwd: Path | None = None) -> tuple[float, float]:
    """Wall and CPU (user + system of the process and its children) seconds of one process."""
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(list(argv), env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True)
    wall = time.perf_counter() - t0
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {done.returncode}: {done.stderr[-2000:]}")
    return wall, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def paired(sides: Sequence[Side], run: Callable[[Side, int], tuple[float, float]], repeat: int
           ) -> dict[str, list[tuple[float, float]]]:
    """``run(side, i)`` for every side, interleaved ``repeat`` times; (wall, CPU) per side."""
    out: dict[str, list[tuple[float, float]]] = {s.name: [] for s in sides}
    for i in range(repeat):
        for side in sides:
            out[side.name].append(run(side, i))
    return out


def median(values: Sequence[float]) -> float:
    return float(statistics.median(values))


def first_record_s(folder: Path, started: float) -> float:
    """Seconds from ``started`` (epoch [s]) to the first JSON record in ``folder`` (a run's first
    finished point or sample); NaN without any."""
    stamps = [p.stat().st_mtime for p in folder.glob("*.json")]
    return min(stamps) - started if stamps else float("nan")


def workflow_run(
    sides: Sequence[Side], side: Side, i: int, tmp: Path, command: str, spec: Path, workers: int,
    records: str, unit: str, first: dict[str, list[float]], check: Callable[[Path], None],
) -> tuple[float, float]:
    """Run ``i`` of ``side``: one whole ``bench-sim COMMAND SPEC --out DIR --workers N`` process
    into ``tmp``; ``check(DIR)`` raises when the run did not finish its work. Appends the time to
    the first record in ``DIR/records`` to ``first[side.name]``, prints a line (``unit``: what a
    record is) and returns (wall, CPU) [s]."""
    out = tmp / f"{'ab'[sides.index(side)]}_{i}"
    started = time.time()
    # cwd: a folder without a bench_sim package (``python -m`` puts the cwd first on sys.path,
    # ahead of the side's PYTHONPATH: run from the checkout, both sides would be the checkout)
    wall, cpu = side.bench_sim(command, str(spec), "--out", str(out), "--workers", str(workers), cwd=tmp)
    check(out)
    first[side.name].append(first_record_s(out / records, started))
    print(f"  {side.name:<22} run {i}: {wall:6.1f} s wall, {cpu:6.1f} s CPU, first {unit} after "
          f"{first[side.name][-1]:5.1f} s ({load_line()})", flush=True)
    return wall, cpu


def print_rates(sides: Sequence[Side], times: dict[str, list[tuple[float, float]]],
                first: dict[str, list[float]], n: int, unit: str,
                extra: tuple[str, dict[str, int]] | None = None) -> None:
    """The medians of paired runs of ``n`` ``unit`` each: wall, CPU, ``unit`` per minute, the
    time to the first one, an ``extra`` column (name, value per side), and the ratio of rates."""
    head = f"  {'side':<22} {'wall s':>7} {'CPU s':>7} {unit + '/min':>12} {'first ' + unit[:-1] + ' s':>15}"
    print(head + (f" {extra[0]:>8}" if extra else "") + f"   (medians of {len(times[sides[0].name])})")
    rate = {}
    for side in sides:
        wall = median([t[0] for t in times[side.name]])
        cpu = median([t[1] for t in times[side.name]])
        rate[side.name] = 60.0 * n / wall
        row = (f"  {side.name:<22} {wall:7.1f} {cpu:7.1f} {rate[side.name]:12.2f} "
               f"{median(first[side.name]):15.1f}")
        print(row + (f" {extra[1][side.name]:8d}" if extra else ""))
    if len(sides) == 2:
        ratio = rate[sides[0].name] / rate[sides[1].name]
        print(f"  {unit} per minute, this checkout / baseline: {ratio:.2f}")
    print(f"  {load_line()} (at the end; CPU s: the process and its workers, user + system)")


def load_line() -> str:
    """The 1, 5 and 15 minute load averages and the number of CPUs, one line."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} CPUs"
