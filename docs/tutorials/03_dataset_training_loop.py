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
# `bench-sim dataset` makes many samples, each one simulation of its own bench, with the exact
# truth behind every pixel. Here: twelve tiny samples (48 x 48, stages 2 and 16) of the default
# rig, with the window on the spot's edge (where the light changes along the TDI window) and the
# light set so that stage 16 clips; then a tiny model in plain numpy, trained on the **true HDR
# target** `true_hdr_dn`, that beats the paper's eq. 11 against that target where pixels clip.
# `--workers 0` runs in this process.

# %%
import subprocess
import sys
from pathlib import Path

import numpy as np


def bench_sim(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "bench_sim", *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


if not Path("start").is_dir():  # made by tutorial 1 when they run in one folder
    bench_sim("init", "start")
Path("tiny_dataset.toml").write_text('''
name = "tiny"
base = "start/paper_rig.toml"
samples = 12
seed = 7
stages = [2, 16]
lines = 48
columns = 48
splits = { train = 0.5, val = 0.25, test = 0.25 }

[config]
sensor = { rows = 24 }
fusion = { mu1 = 2, mu2 = 16 }
render = { spp = 4 }
target = { layout = "dead_leaves", panel_lines = 64, panel_columns = 64 }

[scene]
window_across_mm = [0.0, 0.6, -0.6]       # the window's centre: on the spot's edge
peak_of_mu2_clip = { dist = "loguniform", low = 1.5, high = 6.0 }   # brightest pixel / stage-16 clip
''')
print(bench_sim("dataset", "tiny_dataset.toml", "--out", "tiny", "--workers", "0"))

# %% [markdown]
# The folder holds `data.zarr`, a manifest (one row per sample: its split, drawn values, light
# scale and metrics; plain CSV), the dataset card `README.md` and one record per finished sample.
# The splits have exact sizes: half of 12 is 6, a quarter 3.

# %%
import pandas as pd

from bench_sim.dataset import iter_batches, score_fusion, split_samples

manifest = pd.read_csv("tiny/manifest.csv")
print(manifest[["sample", "split", "scene.window_across_mm", "scene.peak_of_mu2_clip", "light_scale"]])
sizes = {k: len(split_samples("tiny", k)) for k in ("train", "val", "test")}
print(sizes)
assert sizes == {"train": 6, "val": 3, "test": 3}

# %% [markdown]
# The target is `true_hdr_dn`: the noise-free stage-16 signal without any clip, in stage-16 DN
# (what an ideal HDR image holds). Eq. 11 predicts from stage 2 whether stage 16 fits in the word;
# where the light changes along the window, stage 16 can clip where stage 2 says it does not, and
# eq. 11 keeps the clipped value. The tiny model switches on stage 16's own word instead: stage 16
# where its word is below `top - theta`, else stage 2 scaled by `k * 16 / 2`. Its gain `k` is fitted
# by gradient descent on mini-batches of the training pixels, `theta` chosen on the validation
# split; both scored against `true_hdr_dn` where it is recoverable (`hdr_recoverable`).

# %%
MU1, MU2, PEDESTAL, TOP = 2, 16, 64.0, 4095.0
FIELDS = ["dn", "true_hdr_dn", "hdr_recoverable"]


def split(name: str) -> dict[str, np.ndarray]:
    return next(iter_batches("tiny", split=name, fields=FIELDS, batch_size=64))


def predict(dn: np.ndarray, k: float, theta: float) -> np.ndarray:
    s1 = dn[..., 0, :, :].astype(np.float64) - PEDESTAL  # the stages' signals: words less the pedestal
    s2 = dn[..., 1, :, :].astype(np.float64) - PEDESTAL
    return np.where(dn[..., 1, :, :] < TOP - theta, s2, k * MU2 / MU1 * s1)


def loss(b: dict[str, np.ndarray], k: float, theta: float) -> float:
    ok = b["hdr_recoverable"] & (b["true_hdr_dn"] > 1)
    err = (predict(b["dn"], k, theta) - b["true_hdr_dn"]) / b["true_hdr_dn"]
    return float(np.mean(err[ok] ** 2))


train, val = split("train"), split("val")
rng = np.random.default_rng(0)
fits = []
for theta in (0.0, 16.0, 64.0, 256.0):
    ok = train["hdr_recoverable"] & (train["true_hdr_dn"] > 1) & (train["dn"][:, 1] >= TOP - theta)
    x = MU2 / MU1 * (train["dn"][:, 0].astype(np.float64) - PEDESTAL)[ok] / train["true_hdr_dn"][ok]
    k = 1.0
    for _epoch in range(20):  # relative squared error (k x - 1)^2, mini-batches of pixels
        for batch in np.array_split(rng.permutation(x.size), 8):
            k -= 0.5 * float(np.mean(2.0 * (k * x[batch] - 1.0) * x[batch]))
    fits.append((loss(val, k, theta), k, theta))
    print(f"theta {theta:5.0f} DN: k = {k:.4f}, validation loss {fits[-1][0]:.2e}")
_, k, theta = min(fits)

# %% [markdown]
# Both fusions scored on the test split against the true target
# (`bench_sim.dataset.score_fusion`): bias and RMS of the relative error per region. `clipped`
# holds the recoverable pixels where some stage is not clear of its clips: where the fusion has to
# choose, and eq. 11 errs.

# %%
eq11 = score_fusion("tiny", "gamma_hdr", split="test", variables=["dn"]).regions
model = score_fusion("tiny", lambda s: predict(s.arrays["dn"], k, theta), split="test",
                     variables=["dn"]).regions
for region in ("whole", "clipped", "spot_edge", "fill"):
    a, b = eq11[region], model[region]
    print(f"{region:10s} eq. 11 {a['bias']:+.2%} / {a['rms']:.2%}   model {b['bias']:+.2%} / {b['rms']:.2%}"
          f"   ({a['pixels']} pixels)")
assert model["clipped"]["pixels"] > 100
assert model["clipped"]["rms"] < eq11["clipped"]["rms"]
