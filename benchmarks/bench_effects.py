"""Benchmark: the sensor's chain of effects (issue 33) -- the default chain as fast as 0.3.0, and
what each effect's generic path costs.

Prints
* the default chain (no ``[sensor.effects]``): pixel-frames per CPU second of the one-thread
  sensor + DTDI pass of ``bench_sensor.py`` (100 x 1024 pixels, 1,123 frames, stages 10 and 80,
  ``hybrid`` sampler, ``BENCH_SIM_THREADS=1``) of this checkout against 0.3.0's revision
  (:data:`BASELINE_0_3_0`, ``--baseline``), paired and interleaved in one run (each run its own
  process, ``baseline.py``); the ratio must lie within 5 % (``--tolerance``): the line says
  ``within`` or ``OUTSIDE``;
* each effect of :data:`EFFECTS` on this checkout, interleaved with the default chain at the same
  size (``--effect-frames``, fewer frames: the generic path is slower): its rate and its cost
  relative to the default chain (CPU seconds per pixel-frame, ``x``). Effects that only change
  the fixed maps (hot and cold pixels) keep the compiled fast path; the others (a response, row
  noise, telegraph or stuck pixels, an offset pattern, a plug-in) are drawn step by step in
  float64 (:mod:`bench_sim.sensor.chain_draw`).

The load average is printed at the start and the end: the machine is shared, and paired runs are
what the ratios rest on.

Run: ``.venv/bin/python benchmarks/bench_effects.py [--repeat 3] [--baseline REV]
[--effect-frames 283] [--no-effects]`` (about 2 minutes with 3 repeats on an idle core).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from baseline import Side, load_line, median, paired
from bench_sensor import LINES, PAPER_STAGES, ROWS, pass_rate

from bench_sim.sensor.dtdi import frames_needed

#: 0.3.0's revision: the default chain before the effects (the last commit before issue 33)
BASELINE_0_3_0 = "638a481"
COLS = 1024

#: the timed pass of one chain on this checkout: argv = frames, stages, effects (JSON); prints
#: the pixel-frames per CPU second and the CPU seconds of the pass (as bench_sensor.PASS_SCRIPT)
EFFECT_SCRIPT = """
import json, sys, time
import numpy as np
from bench_sim.config import DTDIConfig, SensorConfig
from bench_sim.sensor.stream import iter_sensor_dtdi

n_frames, effects = int(sys.argv[1]), json.loads(sys.argv[3])
stages = [int(m) for m in sys.argv[2].split(",")]
rows, cols, period = 100, 1024, 1024
scene = np.random.default_rng(0).uniform(0.0, 3000.0, size=(period, cols)).astype(np.float32)
idx = np.arange(rows)
frames = [scene[(np.arange(s, min(s + 16, n_frames))[:, None] - idx[None, :]) % period]
          for s in range(0, n_frames, 16)]
sensor = SensorConfig(rows=rows, columns=cols, effects=effects)

def run(chunks):
    n = 0
    for got in iter_sensor_dtdi(iter(chunks), sensor, DTDIConfig(), 100e-6, stages, 1):
        n += len(got[stages[-1]])
    return n

run(frames[:8])  # warm-up: imports, the plug-in's check, first allocations
t0 = time.process_time()
run(frames)
cpu = time.process_time() - t0
print(n_frames * rows * cols / cpu, cpu)
"""

#: a plug-in of the benchmark: a gamma curve (written to a temporary file)
PLUGIN = "def gamma(e, *, rng, g):\n    return 13500.0 * (e / 13500.0) ** g\n"


def effects(plugin_file: Path) -> dict[str, dict]:
    """name -> the ``[sensor.effects]`` table of one chain (every built-in effect alone, and a
    plug-in)."""
    return {
        "nonlinearity (soft knee)": {"k": {"kind": "nonlinearity", "compression": 0.05}},
        "nonlinearity (polynomial)": {"k": {"kind": "nonlinearity", "form": "polynomial",
                                            "coefficients": [-0.05]}},
        "defects: hot, warm, cold (maps only)": {
            "d": {"kind": "defects", "hot_rate": 0.001, "warm_rate": 0.01, "cold_rate": 0.001}},
        "defects: stuck and telegraph": {"d": {"kind": "defects", "stuck_rate": 0.001, "rts_rate": 0.01}},
        "offset_pattern": {"o": {"kind": "offset_pattern", "rms_e": 1.5}},
        "row_noise": {"r": {"kind": "row_noise", "rms_dn": 1.0}},
        "plugin (gamma curve, charge)": {"p": {"kind": "plugin", "function": f"{plugin_file}:gamma",
                                               "point": "charge", "truth": "monotone", "args": {"g": 0.9}}},
    }


def effect_rate(chain: dict, n_frames: int, stages: list[int]) -> tuple[float, float]:
    """One timed one-thread pass of this checkout with ``chain``: (pixel-frames per CPU second,
    CPU seconds)."""
    side = Side.current()
    argv = [sys.executable, "-P", "-c", EFFECT_SCRIPT, str(n_frames), ",".join(map(str, stages)),
            json.dumps(chain)]
    done = subprocess.run(argv, env=side.env(BENCH_SIM_THREADS="1"), capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the pass exited {done.returncode}: {done.stderr[-2000:]}")
    rate, cpu = done.stdout.split()[-2:]
    return float(rate), float(cpu)


def default_against_baseline(baseline: str, repeat: int, tolerance: float) -> None:
    """The default chain of this checkout against ``baseline``, paired."""
    sides = [Side.current(), Side.of_rev(baseline)]
    runs = paired(sides, lambda side, _i: pass_rate(side, "hybrid", PAPER_STAGES), repeat)
    rates = {name: median([r for r, _ in got]) for name, got in runs.items()}
    print(f"default chain, sensor + DTDI on 1 thread, {ROWS} x {COLS} pixels, {frames_needed(LINES, [ROWS])} "
          f"frames, stages {PAPER_STAGES}; median of {repeat} paired runs:")
    for side in sides:
        each = ", ".join(f"{r / 1e6:.1f}" for r, _ in runs[side.name])
        print(f"  {side.name:<22} {rates[side.name] / 1e6:6.1f} M pixel-frames/CPU s  (runs: {each})")
    ratio = rates[sides[0].name] / rates[sides[1].name]
    verdict = "within" if ratio >= 1.0 - tolerance else "OUTSIDE"
    print(f"  this checkout / {baseline}: {ratio:.3f} ({verdict} the {tolerance:.0%} of the target)")


def effect_costs(n_frames: int, repeat: int) -> None:
    """Every effect of :func:`effects` interleaved with the default chain, at ``n_frames``."""
    with tempfile.TemporaryDirectory() as tmp:
        plugin = Path(tmp) / "bench_gamma.py"
        plugin.write_text(PLUGIN)
        chains = {"default chain": {}, **effects(plugin)}
        runs: dict[str, list[tuple[float, float]]] = {name: [] for name in chains}
        for _ in range(repeat):
            for name, chain in chains.items():
                runs[name].append(effect_rate(chain, n_frames, PAPER_STAGES))
    rates = {name: median([r for r, _ in got]) for name, got in runs.items()}
    base = rates["default chain"]
    print(f"each effect on this checkout, {ROWS} x {COLS} pixels, {n_frames} frames, stages {PAPER_STAGES}; "
          f"median of {repeat} interleaved runs:")
    for name, rate in rates.items():
        print(f"  {name:<38} {rate / 1e6:6.1f} M pixel-frames/CPU s   "
              f"cost {base / rate:5.2f}x the default chain")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline", default=BASELINE_0_3_0, help="git revision of the default chain's target")
    ap.add_argument("--tolerance", type=float, default=0.05, help="allowed relative slow-down")
    ap.add_argument("--effect-frames", type=int, default=283, help="frames of the effects' passes")
    ap.add_argument("--no-effects", action="store_true", help="only the default chain against the baseline")
    ap.add_argument("--no-baseline", action="store_true", help="only the effects' costs")
    a = ap.parse_args()
    print(f"{load_line()} at the start")
    if not a.no_baseline:
        default_against_baseline(a.baseline, a.repeat, a.tolerance)
    if not a.no_effects:
        effect_costs(a.effect_frames, a.repeat)
    print(f"{load_line()} at the end")


if __name__ == "__main__":
    main()
