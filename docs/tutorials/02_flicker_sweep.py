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
# # Tutorial 2: a flicker study with `bench-sim sweep`
#
# A lamp on mains flickers; how much banding is left in each DTDI stage? A sweep spec names a
# base bench, fixed overrides and the keys to vary; every point is one simulation with its truth
# and metrics. The bench is tiny (24 rows, 64 columns, 200 lines) so the sweep takes seconds;
# `--workers 0` runs it in this process (no Dask cluster).

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

# %% [markdown]
# The fill alone lights a uniform print and flickers with depth 1 (it goes dark at its troughs).
# With a line period of 1 ms, a 50 Hz flicker has a period of 20 lines and 100 Hz of 10 lines.

# %%
Path("flicker.toml").write_text('''
name = "flicker_tiny"
base = "start/paper_rig.toml"
seed = 0
mode = "product"

[overrides]
lines = 200
sensor = { rows = 24, columns = 64 }
target = { layout = "uniform", panel_lines = 64, panel_columns = 64 }
timing = { line_period_s = 1e-3 }
fusion = { mu1 = 2, mu2 = 20 }
render = { spp = 4 }
lights.strong = { enabled = false }
lights.weak = { irradiance_w_m2 = 0.5, flicker_depth = 1.0 }

[[parameters]]
key = "lights.weak.flicker_hz"
values = [0.0, 50.0, 100.0]
''')
print(bench_sim("sweep", "flicker.toml", "--out", "flicker", "--workers", "0", "--no-plots"))

# %% [markdown]
# `points.csv` has one row per point (units in `points.csv.json`); `sweep.nc` the same as an xarray
# dataset with one dimension per swept key. The banding columns give, per stage, the amplitude of
# the along-track component at the flicker frequency, relative to the mean.

# %%
import xarray as xr

sw = xr.open_dataset("flicker/sweep.nc")
print("flicker_hz:", sw["lights.weak.flicker_hz"].values)
for name in sorted(v for v in sw.data_vars if v.startswith("banding_weak_stage_")):
    print(name, np.round(sw[name].values, 4))  # nan: a steady light has no banding

# %% [markdown]
# DTDI averages a sinusoid over `m` line periods: the amplitude left at stage `m` is
# `|sin(pi f m T) / (pi f m T)|`. At 50 Hz, stage 20 spans one whole period (20 ms) and the banding
# vanishes; at 100 Hz stage 20 spans two. Stage 2 keeps nearly all of it.

# %%
def left(f_hz: float, m: int, t_s: float = 1e-3) -> float:
    x = np.pi * f_hz * m * t_s
    return abs(np.sin(x) / x)


for f in (50.0, 100.0):
    got = float(sw["banding_weak_stage_020"].sel({"lights.weak.flicker_hz": f}))
    print(f"{f:g} Hz, stage 20: measured {got:.4f}, closed form {left(f, 20):.4f}")
    assert got < 0.02
    got2 = float(sw["banding_weak_stage_002"].sel({"lights.weak.flicker_hz": f}))
    print(f"{f:g} Hz, stage 2: measured {got2:.3f}, closed form {left(f, 2):.3f}")
    assert abs(got2 - left(f, 2)) < 0.01
