"""A Dask worker that runs sweep points and data set samples never imports xarray, pandas or Dask's
arrays (~1 s of CPU per worker process): the points and samples read the pass's arrays
(:meth:`bench_sim.pipeline.PassResult.read`), not its dataset. Run in a fresh process, so its
``sys.modules`` holds only what the work imported."""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from bench_sim.workflows.dataset.run import SampleTask, _scene_values
from bench_sim.workflows.dataset.spec import check_sample_configs, load_spec, sample_streams
from bench_sim.workflows.dataset.targets import recorded_values
from bench_sim.workflows.sweep.run import plan_sweep

ROOT = Path(__file__).resolve().parents[2]
RIG = ROOT / "bench_sim" / "scenes" / "paper_rig.toml"
#: what a worker must not import
HEAVY = ("xarray", "pandas", "dask.array")

#: the light-power bench sweep (the paper rig, quick)
BENCH_SPEC = f"""
name = "bench_light_power"
base = "{RIG}"
quick = true
seed = 0
[[parameters]]
key = "lights.strong.irradiance_w_m2"
logspace = {{ start = 8.0, stop = 256.0, num = 6 }}
"""

#: slanted edges (the sharpness columns) under the spot and a flickering fill (the banding columns)
EDGES_SPEC = f"""
name = "edges_flicker"
base = "{RIG}"
quick = true
seed = 3
stages = [5, 80]
[overrides]
target = {{ layout = "slanted_edges" }}
timing = {{ line_period_s = 1e-3, integration_time_s = 0.6e-3 }}
lights.weak = {{ enabled = false }}
[[parameters]]
key = "lights.lamp.kind"
values = ["fill"]
[[parameters]]
key = "lights.lamp.irradiance_w_m2"
values = [0.5]
[[parameters]]
key = "lights.lamp.flicker_hz"
values = [100.0]
"""

#: run in the fresh process: each task as a worker runs it (its shared inputs made first, as
#: the execution layer's tasks), then the heavy modules it holds
WORKER = """
import json, pickle, sys
from bench_sim.workflows.dataset.run import make_sample, sample_inputs
from bench_sim.workflows.sweep.point import measure_point, point_inputs
points, samples = pickle.load(open(sys.argv[1], "rb"))
heavy = {heavy!r}
before = [m for m in heavy if m in sys.modules]
done = []
for task, inputs in zip(points, point_inputs(points)[0]):
    rec = measure_point(task, *(s.func(s.arg) for s in inputs))
    done.append({{"mtf50": rec["mtf50_along_gamma1"], "banding": len(rec["banding_images"])}})
for task, inputs in zip(samples, sample_inputs(samples)):
    out = make_sample(task, *(s.func(s.arg) for s in inputs))
    done.append({{"arrays": len(out.arrays), "metrics": len(out.metrics)}})
print(json.dumps({{"before": before, "after": [m for m in heavy if m in sys.modules], "done": done}}))
"""


def _sample_tasks() -> list[SampleTask]:
    """One ``slanted_edges`` and one ``dead_leaves`` sample of the example data set, as the run makes them."""
    spec = load_spec(ROOT / "bench_sim" / "scenes" / "datasets" / "example.toml")
    values = [recorded_values(spec.draw(i), spec.base.target.layout) for i in range(spec.samples)]
    pick = {layout: next(i for i, v in enumerate(values) if v["target.layout"] == layout)
            for layout in ("slanted_edges", "dead_leaves")}
    planned = check_sample_configs(spec, {i: values[i] for i in pick.values()})
    return [SampleTask(i, planned[i], spec.stages, sample_streams(spec.seed, i)[1], None,
                       _scene_values(values[i])) for i in pick.values()]


@pytest.mark.slow
def test_points_and_samples_import_no_xarray_pandas_or_dask_array(tmp_path: Path) -> None:
    points = []
    for name, text in (("bench", BENCH_SPEC), ("edges", EDGES_SPEC)):
        (tmp_path / f"{name}.toml").write_text(text)
        points.append(plan_sweep(tmp_path / f"{name}.toml", tmp_path / f"{name}_out").tasks[0])
    assert points[1].cfg.target.layout == "slanted_edges" and points[1].flicker_lights == ("lamp",)
    samples = _sample_tasks()
    with open(tmp_path / "tasks.pkl", "wb") as f:
        pickle.dump((points, samples), f)
    proc = subprocess.run(
        [sys.executable, "-c", WORKER.format(heavy=HEAVY), str(tmp_path / "tasks.pkl")],
        capture_output=True, text=True, cwd=ROOT, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["before"] == []
    # the work was done: the slanted edges measured, the banding table made, the samples' arrays
    bench, edges, *made = got["done"]
    assert bench["mtf50"] is None and edges["mtf50"] is not None and edges["banding"] > 0
    assert all(s["arrays"] > 0 and s["metrics"] > 0 for s in made)
    assert got["after"] == [], f"a worker's point or sample imported {got['after']}"
