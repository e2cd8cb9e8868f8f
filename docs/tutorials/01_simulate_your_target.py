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
# # Tutorial 1: simulate your own target and read it with xarray
#
# You have a printed chart (here: a picture we draw ourselves) and want to know what the DTDI
# camera makes of it: the stage images, and the exact truth behind every pixel. Run this in a
# scratch folder (the test suite runs it in a temporary one). It takes a few seconds: the bench
# is made small (a 24-row sensor, 64 columns, 64 lines).
#
# Start from the shipped examples: `bench-sim init start` copies the paper rig, the presets and
# the specs into `start/`.

# %%
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image


def bench_sim(*args: str) -> str:
    """Run ``bench-sim ARGS`` (as from a shell) and return what it printed."""
    done = subprocess.run([sys.executable, "-m", "bench_sim", *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


if not Path("start").is_dir():  # the tutorials run one after another in one folder: init once
    print(bench_sim("init", "start"))

# %% [markdown]
# Draw a target: an 8-bit grey ramp with three dark bars, as a PNG. Integer images are mapped
# onto the config's reflectance range `[reflectance_min, reflectance_max]` (0.02..0.9 by default),
# through the sRGB curve unless `image_encoding = "linear"`.

# %%
ramp = np.tile(np.linspace(20, 255, 256), (256, 1))
ramp[:, 40:56] = ramp[:, 120:136] = ramp[:, 200:216] = 0
Image.fromarray(ramp.astype(np.uint8)).save("my_target.png")

# %% [markdown]
# A config names the paper rig as its `base` and changes only what differs. `bench-sim config
# keys target` lists every setting of the target table with its type, unit and default.

# %%
Path("my_bench.toml").write_text('''
base = "start/paper_rig.toml"
name = "my_target"
lines = 64

[target]
layout = "image"
image = "my_target.png"          # relative to this file
image_fit = "stretch"
panel_lines = 64
panel_columns = 64

[sensor]
rows = 24
columns = 64

[fusion]
mu1 = 2
mu2 = 16
''')
print(bench_sim("config", "keys", "target.image"))

# %% [markdown]
# A value in the wrong unit is refused before anything runs, naming the key as you wrote it and
# guessing what you meant (here a line period written in microseconds):

# %%
Path("slip.toml").write_text('base = "my_bench.toml"\n[timing]\nline_period_s = 100\n')
done = subprocess.run([sys.executable, "-m", "bench_sim", "simulate", "slip.toml", "--out", "slip"],
                      capture_output=True, text=True)
print(done.returncode, done.stderr.strip())
assert done.returncode == 2 and "did you mean 100e-6?" in done.stderr and not Path("slip").exists()

# %% [markdown]
# Simulate stages 2 and 16 (and their eq. 11 fusion). The command ends with a summary: what it
# wrote, the clipped fraction of every stage, and how to open it.

# %%
print(bench_sim("simulate", "my_bench.toml", "--stages", "2,16", "--seed", "1", "--out", "sim"))

# %% [markdown]
# Open the Zarr store with xarray. Every variable has its `units`; the attributes carry the
# resolved config, its SHA-256, the seed and the version.

# %%
import xarray as xr

ds = xr.open_zarr("sim/simulation.zarr").load()  # small: into memory (lazy with Dask otherwise)
print(ds)
print({name: ds[name].attrs.get("units") for name in ds.data_vars})

# %% [markdown]
# `dn` are the words the camera outputs (with the 64 DN pedestal), `mean_dn` their exact
# expectation, `photons` the mean photons each stage pixel collected. Above the pedestal the
# clean signal is `K * QE * photons` (K = 0.072 DN/e-, QE = 0.55 on the paper rig), up to each
# pixel's 1 % PRNU and its few dark electrons, at every stage:

# %%
pedestal = 64
ok = ~ds["clipped"]
gain = ((ds["mean_dn"] - pedestal) / ds["photons"]).where(ok & (ds["photons"] > 1000))
for m in (2, 16):
    print(f"stage {m}: DN per photon {float(gain.sel(stage=m).median()):.5f} (K * QE = {0.072 * 0.55:.5f})")
    assert abs(float(gain.sel(stage=m).median()) / (0.072 * 0.55) - 1) < 0.02

# %% [markdown]
# Stage 16 sums 8 times the rows of stage 2, so it collects about 8 times the light (not exactly:
# its rows see the drum from slightly different angles):

# %%
clean = (ds["mean_dn"] - pedestal).where(ok.all("stage"))
print(f"stage 16 / stage 2 = {float(clean.sel(stage=16).sum() / clean.sel(stage=2).sum()):.3f}")

# %% [markdown]
# The truth follows the drawing: the three dark bars are the lowest reflectance of every line.

# %%
refl = ds["reflectance"].sel(stage=2).mean("line").values
print(np.round(refl[::4], 3))
assert refl.min() < 0.05 < 0.5 < refl.max()
