"""Ctrl-C and SIGTERM at random moments of real ``bench-sim`` runs, under load: one line, the
signal's exit status, no hang, nothing partial left behind.

For each command (``simulate``, ``reproduce``, ``sweep``, ``dataset``, ``design``: small presets,
the three many-run commands on a local Dask cluster of 2 workers) the script first times one run without
a signal (the window of the random moments is 1.1 times that, so they fall anywhere from the
interpreter's start to its exit; ``--window`` sets it instead), then starts the command N times
and sends a signal at a uniformly random moment: SIGINT to the whole process group (as a
terminal's Ctrl-C does) and SIGTERM to the process (as ``kill`` does), alternately. ``--burn K``
keeps K busy-looping processes running meanwhile (load: the command is descheduled at any
point).

Each run must end within ``--timeout`` seconds of the signal, and

* when the command was still running at the signal: exit status 130 (SIGINT) or 143 (SIGTERM),
  never 0; its stderr ends with the one line ``bench-sim: interrupted: ...`` (``terminated``),
  with no other line than those of the run without a signal (warnings), no traceback and no
  ``Fatal Python error``;
* when it had finished: exit status 0 and a complete output;
* when bench_sim had not started yet (the interpreter's own start-up, before bench_sim's first
  statement installs its handlers: seen from the process's ``SigCgt`` mask): not 0, nothing
  written; how Python itself ends is its own (SIGTERM: killed by the signal; SIGINT: its
  ``KeyboardInterrupt`` traceback, or "Fatal Python error: init_import_site" and 1 while it
  imports ``site``), or the handled outcome above if the handlers came in between;
* always: no temporary (``.partial-``, ``.old-``) and no lock file left, an output folder that
  is complete (its completion record) or absent, or for ``sweep``/``dataset``/``design`` a folder of
  finished records to ``--resume``; no process of the run's session still alive 15 s later
  (worker processes included).

Prints one line per failure and a summary per command; exit status 1 when any run failed.

Usage: ``python scripts/ctrl_c_stress.py [-n 50] [--commands simulate,reproduce,sweep,dataset,design]
[--burn 2] [--window S] [--seed 0] [--timeout 60]``
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
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "bench_sim" / "scenes" / "paper_rig.toml"
TINY = f"""base = "{PAPER}"
name = "tiny"
lines = 48
[sensor]
rows = 12
columns = 48
[target]
panel_lines = 48
panel_columns = 48
[render]
spp = 8
[fusion]
mu1 = 2
mu2 = 8
"""
SWEEP = """base = "tiny.toml"
seed = 11
[[parameters]]
key = "lights.strong.irradiance_w_m2"
values = [64.0, 256.0]
[[parameters]]
key = "lights.weak.irradiance_w_m2"
values = [3.0, 12.0]
"""
DATASET = """base = "tiny.toml"
samples = 4
seed = 1
stages = [2, 8]
lines = 16
columns = 48
[randomize]
"lights.strong.irradiance_w_m2" = { dist = "loguniform", low = 32.0, high = 512.0 }
"""
DESIGN = """base = "tiny.toml"
seed = 5
rules = ["eq11", "clip"]
chain_dr = "chosen"
objectives = ["dr_db", "truth_rms", "clipped_share", "snr_dark"]
[[parameters]]
key = "timing.line_period_s"
values = [80e-6, 120e-6]
"""
#: command -> arguments ({out}: the run's output folder, {specs}: the folder of the files above)
COMMANDS = {
    "simulate": ["simulate", "{specs}/tiny.toml", "--stages", "2,8", "--out", "{out}"],
    "reproduce": ["reproduce", "--quick", "--out", "{out}"],
    "sweep": ["sweep", "{specs}/sweep.toml", "--out", "{out}", "--workers", "2", "--no-plots"],
    "dataset": ["dataset", "{specs}/dataset.toml", "--out", "{out}", "--workers", "2"],
    "design": ["design", "{specs}/design.toml", "--out", "{out}", "--workers", "2", "--no-plots"],
}
RESUMABLE = {"sweep", "dataset", "design"}
LINE = {signal.SIGINT: "bench-sim: interrupted: ", signal.SIGTERM: "bench-sim: terminated: "}
STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143}


def write_specs(folder: Path) -> None:
    """The small config and specs the presets run."""
    (folder / "tiny.toml").write_text(TINY)
    (folder / "sweep.toml").write_text(SWEEP)
    (folder / "dataset.toml").write_text(DATASET)
    (folder / "design.toml").write_text(DESIGN)


def _env() -> dict[str, str]:
    # faulthandler: a hung run is sent SIGABRT and dumps every thread's stack before it is killed
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "default", "PYTHONFAULTHANDLER": "1"}
    env.pop("BENCH_SIM_DEBUG", None)
    return env


def _start(command: str, specs: Path, out: Path) -> subprocess.Popen:
    args = [a.replace("{out}", str(out)).replace("{specs}", str(specs)) for a in COMMANDS[command]]
    return subprocess.Popen([sys.executable, "-m", "bench_sim", *args], cwd=out.parent, env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _session_alive(sid: int) -> list[int]:
    """Processes of session ``sid`` still alive (zombies are not)."""
    alive = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if fields[0] != "Z" and int(fields[3]) == sid:
            alive.append(int(entry))
    return alive


def _kill_session(sid: int) -> None:
    for pid in _session_alive(sid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


def timed_run(command: str, specs: Path, folder: Path, timeout_s: float) -> tuple[float, list[str]]:
    """One run without a signal: its wall time [s] and its stderr lines (must succeed)."""
    out = folder / f"{command}-plain"
    t0 = time.perf_counter()
    proc = _start(command, specs, out)
    try:
        _, err = proc.communicate(timeout=timeout_s * 10)
    finally:
        _kill_session(proc.pid)
    if proc.returncode != 0:
        raise SystemExit(f"{command}: the run without a signal failed (exit {proc.returncode}): "
                         f"{err[-2000:]}")
    return time.perf_counter() - t0, _lines(err)


@dataclass
class Outcome:
    ok: bool
    what: str
    finished_first: bool = False
    before_start: bool = False


def _catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (its ``SigCgt`` mask)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return bool(int(status.split("SigCgt:")[1].split()[0], 16) >> (sig - 1) & 1)


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has ended but is not yet reaped (a zombie: a signal sent to it is
    lost, and its exit status is the one it ended with)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    return status.split("State:")[1].split()[0] in ("Z", "X")


def _leftovers(folder: Path, out: Path, command: str) -> list[str]:
    problems = []
    left = sorted(p.name for p in folder.iterdir() if ".partial-" in p.name or ".old-" in p.name
                  or p.name == f".{out.name}.lock")
    if left:
        problems.append(f"left {left}")
    complete = (out / ".bench-sim-output.json").is_file()
    if out.exists() and not complete and command not in RESUMABLE:
        problems.append(f"left an incomplete {out.name}/")
    return problems


def signalled_run(
    command: str, specs: Path, folder: Path, sig: int, delay_s: float, timeout_s: float, allowed: list[str]
) -> Outcome:
    """Start ``command``, send ``sig`` after ``delay_s`` and check how it ended (module doc)."""
    out = folder / "run"
    proc = _start(command, specs, out)
    time.sleep(delay_s)
    running = proc.poll() is None
    # bench_sim's first statement installs its SIGINT and SIGTERM handlers together; before it,
    # in the interpreter's own start-up, a signal has its default action
    early = running and not _catches(proc.pid, signal.SIGTERM)
    if running and _ended(proc.pid):  # it ended while the above was read: it finished first
        running = False
    if running:
        try:
            if sig == signal.SIGINT:
                os.killpg(proc.pid, sig)  # the whole foreground group, as a terminal does
            else:
                os.kill(proc.pid, sig)
        except ProcessLookupError:
            running = False
    try:
        _, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.kill(proc.pid, signal.SIGABRT)  # faulthandler's dump of every thread, then abort
        try:
            _, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            _kill_session(proc.pid)
            _, err = proc.communicate()
        _kill_session(proc.pid)
        dump = " | ".join(ln.strip() for ln in err.splitlines()[-60:])
        return Outcome(False, f"hung (alive {timeout_s:g} s after the signal); its stacks: {dump}")
    problems = []
    t_end = time.monotonic()
    while _session_alive(proc.pid) and time.monotonic() - t_end < 15:
        time.sleep(0.1)
    stray = _session_alive(proc.pid)
    if stray:
        _kill_session(proc.pid)
        problems.append(f"processes {stray} still alive 15 s after the run ended")
    lines = _lines(err)
    if not running:
        if proc.returncode != 0:
            problems.append(f"finished before the signal with exit {proc.returncode}: {lines[-3:]!r}")
        elif not (out / ".bench-sim-output.json").is_file():
            problems.append("finished before the signal without a complete output")
        return Outcome(not problems, "; ".join(problems) or "finished first", finished_first=True)
    if early and proc.returncode != 0:  # the interpreter's own start-up: its own ending
        problems += _leftovers(folder, out, command)
        return Outcome(not problems, "; ".join(problems) or "before bench_sim started", before_start=True)
    if proc.returncode != STATUS[sig]:
        problems.append(f"exit {proc.returncode}, not {STATUS[sig]}")
    if not lines or not lines[-1].startswith(LINE[sig]):
        problems.append(f"last stderr line not {LINE[sig].strip()!r}: {lines[-3:]!r}")
    extra = [ln for ln in lines[:-1] if ln not in allowed]
    if extra or any("Traceback" in ln or "Fatal Python error" in ln for ln in lines):
        problems.append(f"{len(lines)} stderr lines: {lines[:4]!r}")
    problems += _leftovers(folder, out, command)
    return Outcome(not problems, "; ".join(problems) or "ok")


class Burner:
    """``k`` processes spinning on the CPU while the runs go on (load)."""

    def __init__(self, k: int) -> None:
        self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(k)]

    def __enter__(self) -> Burner:
        return self

    def __exit__(self, *exc: object) -> None:
        for p in self.procs:
            p.kill()
            p.wait()


def stress(command: str, n: int, rng: random.Random, window_s: float | None, timeout_s: float,
           report: list[str]) -> int:
    """``n`` signalled runs of ``command``; the number that failed (each printed)."""
    with tempfile.TemporaryDirectory(prefix="stress-") as tmp:
        specs = Path(tmp)
        write_specs(specs)
        if window_s is None:
            plain, allowed = timed_run(command, specs, specs, timeout_s)
            window = 1.1 * plain
        else:
            plain, allowed, window = float("nan"), [], window_s
        failures = finished = early = 0
        counts = {signal.SIGINT: 0, signal.SIGTERM: 0}
        t0 = time.perf_counter()
        for i in range(n):
            sig = (signal.SIGINT, signal.SIGTERM)[i % 2]
            delay = rng.uniform(0.0, window)
            with tempfile.TemporaryDirectory(prefix="run-", dir=tmp) as run_dir:
                res = signalled_run(command, specs, Path(run_dir), sig, delay, timeout_s, allowed)
            counts[sig] += not (res.finished_first or res.before_start)
            finished += res.finished_first
            early += res.before_start
            if not res.ok:
                failures += 1
                name = signal.Signals(sig).name
                print(f"{command} run {i}: {name} at {delay:.2f} s: {res.what}", flush=True)
        line = (f"{command}: {n - failures} of {n} runs stopped cleanly ({counts[signal.SIGINT]} SIGINT, "
                f"{counts[signal.SIGTERM]} SIGTERM while running, {finished} finished first, {early} before "
                f"bench_sim's first statement; window "
                f"{window:.1f} s, run without a signal {plain:.1f} s; {time.perf_counter() - t0:.0f} s)")
        print(line, flush=True)
        report.append(line)
        return failures


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=50, help="signalled runs per command")
    ap.add_argument("--commands", default="simulate,reproduce,sweep,dataset,design",
                    help=f"comma-separated, of {', '.join(COMMANDS)}")
    ap.add_argument("--burn", type=int, default=2, help="busy-looping processes meanwhile (load)")
    ap.add_argument("--window", type=float, default=None,
                    help="signal within this many seconds [s] (default: 1.1 x a run without a signal)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random moments")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds allowed to stop [s]")
    ns = ap.parse_args(argv)
    commands = [c.strip() for c in ns.commands.split(",") if c.strip()]
    unknown = [c for c in commands if c not in COMMANDS]
    if unknown:
        ap.error(f"unknown command(s) {unknown}; choose from {', '.join(COMMANDS)}")
    rng = random.Random(ns.seed)
    report: list[str] = []
    t0 = time.perf_counter()
    with Burner(ns.burn):
        failures = sum(stress(c, ns.n, rng, ns.window, ns.timeout, report) for c in commands)
    print(f"all: {failures} failed; {ns.burn} CPU burners; {time.perf_counter() - t0:.0f} s")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
