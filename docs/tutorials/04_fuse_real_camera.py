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
# # Tutorial 4: fusing two images from a real camera
#
# `bench-sim fuse` takes the stage-`mu1` and stage-`mu2` images of any DTDI camera (16-bit TIFF or
# PNG, EXR or NPY, integer DN in the `beta`-bit word) and fuses them with the paper's rule
# (eq. 11). Here we stand in for the camera: two 16-bit TIFFs of a 12-bit DTDI camera, stages 10
# and 80, of a scene whose brightness rises along each row. The brighter half clips at stage 80.

# %%
import subprocess
import sys

import numpy as np
import tifffile

rng = np.random.default_rng(1)
signal_1 = np.tile(np.geomspace(2.0, 480.0, 512), (64, 1))  # stage-1 signal per pixel [DN]
low = np.clip(np.round(10 * signal_1 + rng.normal(0, 3, signal_1.shape)), 0, 4095).astype(np.uint16)
high = np.clip(np.round(80 * signal_1 + rng.normal(0, 8, signal_1.shape)), 0, 4095).astype(np.uint16)
tifffile.imwrite("stage10.tiff", low)   # plain files, no metadata: as a camera writes them
tifffile.imwrite("stage80.tiff", high)
print(f"stage 80 clipped: {np.mean(high == 4095):.0%} of the pixels")


def bench_sim(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "bench_sim", *args], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout


# %% [markdown]
# Fuse. `--beta` is the camera's output word. The command says which pedestal it subtracted:
# the files carry no bench_sim metadata, so 0 (bench_sim's own stage images carry their
# `dtdi.pedestal_dn`, which `fuse` then uses).

# %%
out = bench_sim("fuse", "stage10.tiff", "stage80.tiff", "--mu1", "10", "--mu2", "80", "--beta", "12",
                "--out", "hdr.exr", "--tra", "hdr.png")
print(out)
assert "pedestal subtracted: 0 DN" in out

# %% [markdown]
# `hdr.exr` holds `Gamma_HDR` in stage-80 units (channel `Y`) and the stage each pixel came from
# (channel `source`); its header records the inputs' hashes, the stages, the word and the eq. 11
# threshold. Below the threshold (on the stage-10 word) a pixel is stage 80's; above it, stage 10's scaled by 80/10, so
# the fused response is linear over the whole ramp, past where stage 80 clipped.

# %%
from bench_sim.io import read_exr

chans, meta = read_exr("hdr.exr")
hdr, source = chans["Y"], chans["source"]
print({k: meta[k] for k in ("mu1", "mu2", "beta", "threshold_dn", "pedestal_dn")})
truth = 80 * signal_1
rel = np.abs(hdr - truth) / truth
print(f"pixels from stage 10: {np.mean(source == 10):.0%}; median error {np.median(rel):.2%}")
# eq. 11 switches on the stage-10 value, so only pixels at the threshold's noise keep a clipped word
assert np.mean(source[high == 4095] == 10) > 0.99
assert np.median(rel[:, 256:]) < 0.01               # linear where stage 80 had clipped

# %% [markdown]
# A camera whose words carry an offset (a black level or pedestal of, say, 64 DN): say so with
# `--pedestal`, or eq. 11's threshold and the scaled stage-10 values are off by it.

# %%
tifffile.imwrite("stage10_p.tiff", (low.astype(np.int64) + 64).clip(0, 4095).astype(np.uint16))
tifffile.imwrite("stage80_p.tiff", (high.astype(np.int64) + 64).clip(0, 4095).astype(np.uint16))
print(bench_sim("fuse", "stage10_p.tiff", "stage80_p.tiff", "--pedestal", "64", "--out", "hdr_p.exr"))
chans_p, _ = read_exr("hdr_p.exr")
# the same image as without the offset, wherever both runs took a pixel from the same stage (the
# word's top is 64 DN nearer, so the switch moves a little)
same = (chans_p["source"] == source) & (high.astype(np.int64) + 64 < 4095)
print(f"max difference where both took the same stage: {np.abs(chans_p['Y'] - hdr)[same].max():.1f} DN")
assert np.abs(chans_p["Y"] - hdr)[same].max() < 1
assert np.median(np.abs(chans_p["Y"] - truth)[:, 256:] / truth[:, 256:]) < 0.01
