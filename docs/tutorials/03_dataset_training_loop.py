# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Tutorial 3: a synthetic dataset in a training loop
#
# `bench-sim dataset` makes many samples, each one simulation of its own bench with values drawn
# from the spec's distributions, with the exact truth behind every pixel. Here: three tiny
# samples (48 x 48, stages 2 and 16), then a training loop in plain numpy that learns to map the
# stage words back to the print's reflectance. `--workers 0` runs in this process.

# %%
import subprocess
import sys
from pathlib import Path

import numpy as np


def bench_sim(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "bench_sim", *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


bench_sim("init", "start")
Path("tiny_dataset.toml").write_text('''
name = "tiny"
base = "start/paper_rig.toml"
samples = 3
seed = 7
stages = [2, 16]
lines = 48
columns = 48

[config]
sensor = { rows = 24 }
fusion = { mu1 = 2, mu2 = 16 }
render = { spp = 4 }
target = { panel_lines = 64, panel_columns = 64 }
lights.strong = { enabled = false }

[randomize]
"lights.weak.irradiance_w_m2" = { dist = "loguniform", low = 3.0, high = 12.0 }
"target.layout" = { dist = "choice", values = ["dead_leaves", "random_bars"] }
''')
print(bench_sim("dataset", "tiny_dataset.toml", "--out", "tiny", "--workers", "0"))

# %% [markdown]
# The folder holds `data.zarr`, a manifest (one row per sample: seed, drawn values, metrics), the
# dataset card `README.md` and one record per finished sample. `bench_sim.dataset.iter_samples`
# yields the samples as numpy arrays, one at a time, after checking the records.

# %%
import bench_sim

samples = list(bench_sim.dataset.iter_samples("tiny"))
for s in samples:
    print(s.index, s.stages, {k: v.shape for k, v in s.arrays.items()}, s.values)

# %% [markdown]
# A training loop: inputs are the stage-16 words above the 64 DN pedestal, divided by the fill's
# irradiance (what an exposure meter would tell the network); targets the truth reflectance.
# The model is a straight line fitted by gradient descent over mini-batches of pixels; the truth
# is exact, so the only error left is the sensor's noise.

# %%
pedestal = 64.0
xs, ys = [], []
for s in samples:
    ok = ~s.arrays["clipped"][1]
    x = (s.arrays["dn"][1].astype(np.float64) - pedestal) / s.values["lights.weak.irradiance_w_m2"]
    xs.append(x[ok])
    ys.append(s.arrays["reflectance"][1][ok])
x, y = np.concatenate(xs), np.concatenate(ys)
x = (x - x.mean()) / x.std()  # standardised input
rng = np.random.default_rng(0)
w, b, lr = 0.0, 0.0, 0.5
losses = [float(np.mean((w * x + b - y) ** 2))]  # before training
for _epoch in range(30):
    order = rng.permutation(x.size)
    for batch in np.array_split(order, 16):
        pred = w * x[batch] + b
        err = pred - y[batch]
        w -= lr * float(np.mean(err * x[batch]))
        b -= lr * float(np.mean(err))
    losses.append(float(np.mean((w * x + b - y) ** 2)))
print(f"mse before {losses[0]:.2e} -> after 30 epochs {losses[-1]:.2e}")
assert losses[-1] < 0.5 * losses[0]

# %% [markdown]
# The fitted line matches the closed-form least-squares fit, and the residual is the size of
# the sensor's noise relative to the signal (a few percent of the reflectance).

# %%
slope, intercept = np.polyfit(x, y, 1)
print(f"gradient descent w = {w:.4f}, b = {b:.4f}; least squares w = {slope:.4f}, b = {intercept:.4f}")
assert abs(w - slope) < 0.02 * abs(slope) + 1e-3
rms = float(np.sqrt(losses[-1]))
print(f"rms error {rms:.4f} against a mean reflectance of {y.mean():.3f}")
assert rms < 0.1 * y.mean() + 0.01
