"""Start-up time of ``bench-sim --help``: whole processes, this checkout against a baseline revision.

Each run is a separate process (``python -m bench_sim --help``), timed from outside: wall time
and CPU time (user + system). Two states of Python's bytecode cache are timed, because they
differ by about 2x:

* ``cached``: the package's ``.pyc`` files exist (after ``pip install .``, after
  ``scripts/setup.sh``, or after any first run without ``PYTHONDONTWRITEBYTECODE``);
* ``no cache``: every module compiled from source at every start (``PYTHONDONTWRITEBYTECODE=1``
  with an empty ``PYTHONPYCACHEPREFIX``), which is what an editable install gives in an
  environment that sets ``PYTHONDONTWRITEBYTECODE`` and never byte-compiled the package.

Then the import time of ``bench_sim.cli`` by top-level package (``python -X importtime``, self
times summed, cached state; the flag itself adds overhead, so compare the shares, not the sum).

Usage: python benchmarks/bench_startup.py [--repeat 9] [--baseline REV | --no-baseline]
"""

from __future__ import annotations

import argparse
import collections
import compileall
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from baseline import ROOT, Side, add_baseline_args, load_line, median, paired

LIMIT_S = 1.0


def _compile(side: Side) -> None:
    tree = side.tree if side.tree is not None else ROOT
    compileall.compile_dir(str(tree / "bench_sim"), quiet=1)


def _import_shares(side: Side) -> list[tuple[str, float]]:
    """Self import time [ms] per top-level package of ``import bench_sim.cli`` (median of 3)."""
    per: dict[str, list[float]] = collections.defaultdict(list)
    for _ in range(3):
        done = subprocess.run([sys.executable, "-P", "-X", "importtime", "-c", "import bench_sim.cli"],
                              env=side.env(), capture_output=True, text=True, check=True)
        tot: collections.Counter[str] = collections.Counter()
        for line in done.stderr.splitlines():
            m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s*(\S+)", line)
            if m:
                tot[m.group(2).split(".")[0]] += int(m.group(1)) / 1000.0
        for k, v in tot.items():
            per[k].append(v)
    shares = sorted(((k, median(v)) for k, v in per.items()), key=lambda kv: -kv[1])
    return shares[:6]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    add_baseline_args(ap)
    a = ap.parse_args()
    sides = [Side.current()] + ([] if a.no_baseline else [Side.of_rev(a.baseline)])
    for side in sides:
        _compile(side)
    print(f"bench-sim --help, whole processes, median of {a.repeat} paired runs; {load_line()}")
    print(f"  {'side':<22} {'bytecode':<9} {'wall s':>7} {'CPU s':>7} {'< 1 s':>6}")
    with tempfile.TemporaryDirectory() as empty:
        states = {"cached": {}, "no cache": {"PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": empty}}
        walls: dict[tuple[str, str], float] = {}
        for state, env in states.items():
            runs = paired(sides, lambda side, _i, env=env: side.bench_sim("--help", **env), a.repeat)
            for side in sides:
                wall = median([w for w, _ in runs[side.name]])
                cpu = median([c for _, c in runs[side.name]])
                walls[(side.name, state)] = wall
                verdict = "yes" if wall < LIMIT_S else "no"
                print(f"  {side.name:<22} {state:<9} {wall:7.2f} {cpu:7.2f} {verdict:>6}")
    if len(sides) == 2:
        for state in states:
            ratio = walls[(sides[0].name, state)] / walls[(sides[1].name, state)]
            print(f"  {state}: this checkout / baseline = {ratio:.2f}")
    print(f"import bench_sim.cli, self time by package [ms] (-X importtime, cached), {load_line()}")
    for side in sides:
        shares = ", ".join(f"{k} {v:.0f}" for k, v in _import_shares(side))
        print(f"  {side.name:<22} {shares}")
    print(f"(limit {LIMIT_S:.0f} s for bench-sim --help; run from {Path.cwd()})")


if __name__ == "__main__":
    main()
