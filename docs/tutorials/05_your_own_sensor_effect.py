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
# # Tutorial 5: your own sensor effect, with its exact truth
#
# Your camera does something the EMVA 1288 linear model does not: here, its pixels follow a gamma
# curve of the collected charge, and some columns sit under a dust shadow. You write each as a
# Python function in a file next to your config, name it in `[sensor.effects.<name>]`, and say
# whether the simulator may trust it for the truth (`truth = "monotone"`: a deterministic,
# non-decreasing response of the charge) or not (`truth = "none"`). The page
# [sensor effects](../sensor-effects.md) is the reference; this runs the same example in a
# scratch folder (the test suite runs it in a temporary one) in about half a minute.

# %%
import subprocess
import sys
from pathlib import Path

import numpy as np
import xarray as xr


def bench_sim(*args: str, check: bool = True) -> str:
    """Run ``bench-sim ARGS`` (as from a shell) and return what it printed."""
    done = subprocess.run([sys.executable, "-m", "bench_sim", *args], capture_output=True, text=True)
    if check:
        assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


if not Path("start").is_dir():  # the tutorials run one after another in one folder: init once
    print(bench_sim("init", "start"))

# %% [markdown]
# ## The effects, in a file of yours
#
# The contract of an effect is `f(x, *, rng, **args) -> array`: `x` is a float64 array of reads
# (frames, rows, columns) at the point the config names -- electrons after the full-well clip at
# `charge`, the analog value in DN at `analog`, the raw value at `digital` --; the function
# returns an array of the same shape and a real dtype. Any random number comes from `rng` (its
# own stream per effect and chunk of frames: the same seed gives the same images with any number
# of threads or Dask workers). `args` is the config's `args` table.

# %%
Path("my_effects.py").write_text('''
"""Effects of my camera."""

import numpy as np


def gamma_response(e, *, rng, gamma, full_well_e):
    """A gamma curve of the charge: full_well_e * (e / full_well_e) ** gamma [e-]."""
    return full_well_e * (e / full_well_e) ** gamma


def dust(y, *, rng, depth_dn, columns):
    """A dust shadow over some columns, wobbling from read to read [DN]."""
    y[..., columns[0]:columns[1]] -= depth_dn * rng.uniform(0.5, 1.0, y.shape[:-1])[..., None]
    return y
''')

# %% [markdown]
# The config: a 40-row sensor over a uniform panel, the gamma curve declared monotone (its truth
# is exact), the dust declared `truth = "none"` and switched off for now.

# %%
Path("my_camera.toml").write_text('''
base = "start/paper_rig.toml"
name = "my_camera"
lines = 128

[sensor]
rows = 40
columns = 32

[target]
layout = "uniform"
panel_columns = 32

[lights.strong]
enabled = false

[fusion]
mu1 = 1
mu2 = 40

[sensor.effects.gamma]
kind = "plugin"
function = "my_effects.py:gamma_response"
point = "charge"
truth = "monotone"
args = { gamma = 0.9, full_well_e = 13500.0 }

[sensor.effects.dust]
kind = "plugin"
function = "my_effects.py:dust"
point = "analog"
truth = "none"
enabled = false
args = { depth_dn = 8.0, columns = [10, 14] }
''')
print("\n".join(line for line in bench_sim("config", "keys", "sensor").splitlines() if "kind=plugin" in line))

# %% [markdown]
# ## Mistakes are caught before anything runs
#
# The chain is built and checked before any rendering: the function is imported, its signature
# bound, it is called once on a probe, and a response declared monotone is checked to be
# deterministic and never to fall. Here a curve that bends back down is declared monotone:

# %%
Path("my_effects.py").write_text(Path("my_effects.py").read_text() + '''

def bends_back(e, *, rng, gamma, full_well_e):
    return np.where(e < 9000.0, e, 18000.0 - e)
''')
Path("bent.toml").write_text('''
base = "my_camera.toml"
[sensor.effects.gamma]
function = "my_effects.py:bends_back"
''')
message = bench_sim("simulate", "bent.toml", "--out", "out/bent", "--stages", "1,40", check=False)
print(message)
assert message.startswith("bench-sim: error: sensor.effects.gamma") and not Path("out/bent").exists()

# %% [markdown]
# ## Simulate, and check that the truth is exact
#
# Stages 1 and 40. On a uniform panel every line of a stage is a new draw of the same pixels, so
# the z-scores `(dn - mean_dn) / noise_std_dn` of all 128 x 32 words of a stage must have mean 0
# and variance 1 if `mean_dn` and `noise_std_dn` are the exact expectation and noise of `dn`
# through the gamma curve. `linear_dn`, the linear camera, is something else: the curve lifts the
# dark end (its slope at 0 is steep) and compresses the bright end.

# %%
print(bench_sim("simulate", "my_camera.toml", "--out", "out/mine", "--stages", "1,40"))
ds = xr.open_zarr("out/mine/simulation.zarr")
print(ds.attrs["sensor_chain"])
print("truth_exact:", ds.attrs["truth_exact"])
for m in (1, 40):
    d = ds.sel(stage=m)
    z = ((d.dn.astype("float64") - d.mean_dn) / d.noise_std_dn).values.ravel()
    print(f"stage {m}: mean_dn {float(d.mean_dn.mean()):8.1f} DN, linear_dn {float(d.linear_dn.mean()):8.1f} DN; "
          f"z-scores: mean {z.mean():+.3f} (standard error {1 / np.sqrt(z.size):.3f}), variance {z.var():.3f}")
    assert abs(z.mean()) < 5 / np.sqrt(z.size) and abs(z.var() - 1) < 5 * np.sqrt(2 / z.size)

# %% [markdown]
# ## An effect the truth does not know
#
# Switch the dust on. Its effect on a read is unknown to the simulator (`truth = "none"`), so
# `mean_dn` describes the camera without it, and every output says so: the store's attributes,
# every truth variable's, the JSON records of sweeps and data sets.

# %%
Path("dusty.toml").write_text('base = "my_camera.toml"\n[sensor.effects.dust]\nenabled = true\n')
bench_sim("simulate", "dusty.toml", "--out", "out/dusty", "--stages", "1,40")
dusty = xr.open_zarr("out/dusty/simulation.zarr")
print("truth_exact:", dusty.attrs["truth_exact"], "--", dusty.attrs["truth_not_exact"])
print("mean_dn says:", dusty.mean_dn.attrs["truth_exact"])
d = dusty.sel(stage=1)
shadow = float((d.dn.astype("float64") - d.mean_dn)[:, 10:14].mean())
print(f"stage 1 under the dust: dn - mean_dn averages {shadow:.2f} DN (the truth does not know the dust)")
assert dusty.attrs["truth_exact"] == 0 and shadow < -4.0

# %% [markdown]
# Next: a sweep of the gamma (`key = "sensor.effects.gamma.args.gamma"`) or a data set that
# randomises it, as any other config key ([sensor effects](../sensor-effects.md)); a built-in
# effect (non-linearity, defect pixels, an offset pattern, row noise) is a table with its `kind`.
