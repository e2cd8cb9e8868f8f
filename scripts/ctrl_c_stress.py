"""Ctrl-C at random moments of a real ``bench-sim`` run: exit 130, one line, nothing left behind.

Starts ``python -m bench_sim reproduce --quick --out DIR/run`` (or any command given after
``--``) N times, sends SIGINT at a uniformly random time in the first ``--window`` seconds, and
checks every run: exit status 130 (or 0 if it finished first), at most one line on stderr
(``bench-sim: interrupted: ...``), no ``Fatal Python error``, no temporary (``.partial-``,
``.old-``) left in DIR, no process still running after ``--timeout`` seconds. Prints one line per
failure and a summary; exit status 1 when any run failed.

Usage: ``python scripts/ctrl_c_stress.py [-n 50] [--window 3] [--seed 0] [-- COMMAND ARGS]``
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one_run(args: list[str], delay_s: float, timeout_s: float) -> tuple[bool, str]:
    """Run ``bench-sim ARGS`` in a fresh folder, SIGINT after ``delay_s``; (ok, what happened)."""
    with tempfile.TemporaryDirectory(prefix="ctrlc-") as tmp:
        out = Path(tmp) / "run"
        env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "default"}
        env.pop("BENCH_SIM_DEBUG", None)
        cmd = [sys.executable, "-m", "bench_sim", *[a.replace("{out}", str(out)) for a in args]]
        proc = subprocess.Popen(cmd, cwd=tmp, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
        time.sleep(delay_s)
        try:  # the whole group, as a terminal does
            os.killpg(proc.pid, signal.SIGINT)
        except ProcessLookupError:
            pass
        try:
            _, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            return False, f"hung (> {timeout_s} s after SIGINT)"
        lines = [ln for ln in err.splitlines() if ln.strip()]
        left = sorted(str(p.relative_to(tmp)) for p in Path(tmp).rglob("*")
                      if ".partial-" in p.name or ".old-" in p.name)
        if proc.returncode == 0:
            return not left, f"finished before the signal; left {left}" if left else "finished first"
        problems = []
        if proc.returncode != 130:
            problems.append(f"exit {proc.returncode}")
        if len(lines) != 1 or not lines[0].startswith("bench-sim: interrupted:"):
            problems.append(f"{len(lines)} stderr lines: {lines[:3]!r}")
        if left:
            problems.append(f"left {left}")
        if out.exists() and not (out / ".bench-sim-output.json").is_file():
            problems.append(f"left an incomplete {out.name}/")
        return not problems, "; ".join(problems) or "ok"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=50, help="runs")
    ap.add_argument("--window", type=float, default=3.0, help="signal within this many seconds [s]")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random delays")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds allowed to stop [s]")
    ap.add_argument("command", nargs="*", default=["reproduce", "--quick", "--out", "{out}"])
    ns = ap.parse_args()
    rng = random.Random(ns.seed)
    failures = 0
    t0 = time.perf_counter()
    for i in range(ns.n):
        delay = rng.uniform(0.0, ns.window)
        ok, what = one_run(ns.command, delay, ns.timeout)
        if not ok:
            failures += 1
            print(f"run {i}: SIGINT at {delay:.2f} s: {what}", flush=True)
    print(f"{ns.n - failures} of {ns.n} runs stopped cleanly (SIGINT within {ns.window} s; "
          f"{time.perf_counter() - t0:.0f} s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
