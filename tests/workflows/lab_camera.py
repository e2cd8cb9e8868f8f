"""A synthetic lab camera written with numpy alone (not bench_sim's sensor): the camera of issue
35's Must show, for the tests of ``calibrate``.

A 12-bit camera, ``K = 0.25`` DN/e-, QE 0.6, 6 e- read noise, a black offset of 100 DN; its
response compresses the charge as ``r(e) = E tanh(e / E)``, 3 % below linear where the ADC clips,
and the ADC clips before the 20 000 e- full well; dark current 200 e-/s with 10 % non-uniformity,
30 hot pixels (8 000 to 40 000 e-/s more), a 1.5 e- offset pattern, 1 % PRNU. An exposure-time
series at constant irradiance: 40 steps, two flats and two darks each.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class LabCamera:
    shape: tuple[int, int] = (256, 256)
    k: float = 0.25
    qe: float = 0.6
    black_dn: float = 100.0
    bits: int = 12
    full_well_e: float = 20000.0
    read_noise_e: float = 6.0
    dark_current_e_s: float = 200.0
    dark_nu: float = 0.10
    offset_rms_e: float = 1.5
    prnu: float = 0.01
    hot: int = 30
    hot_e_s: tuple[float, float] = (8000.0, 40000.0)
    compression: float = 0.03
    photon_rate: float = 68600.0  # photons per pixel per second
    seed: int = 0
    gain: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rng = np.random.default_rng([self.seed, 1])
        m, n = self.shape
        self.gain = 1.0 + self.prnu * rng.standard_normal(self.shape)
        nu = 1 + self.dark_nu * rng.standard_normal(self.shape)
        self.dark_map = np.maximum(self.dark_current_e_s * nu, 0.0)
        self.offset_e = self.offset_rms_e * rng.standard_normal(self.shape)
        idx = rng.choice(m * n, self.hot, replace=False)
        self.hot_mask = np.zeros(self.shape, bool)
        self.hot_mask.flat[idx] = True
        self.hot_positions = [(int(i // n), int(i % n)) for i in sorted(idx)]
        self.hot_extra = np.zeros(self.shape)
        self.hot_extra.flat[idx] = rng.uniform(*self.hot_e_s, self.hot)
        r_clip = ((1 << self.bits) - 1 - self.black_dn) / self.k  # response electrons at the ADC's top
        lo, hi = 1e-6, 5.0  # tanh(u) / u = 1 - compression at u = e_clip / E
        for _ in range(200):
            u = 0.5 * (lo + hi)
            lo, hi = (u, hi) if np.tanh(u) / u > 1 - self.compression else (lo, u)
        self.e_clip = r_clip / (1 - self.compression)
        self.e_scale = self.e_clip / u
        self.rng = np.random.default_rng([self.seed, 2])

    def response(self, e: np.ndarray) -> np.ndarray:
        return self.e_scale * np.tanh(e / self.e_scale)

    def mean_signal_dn(self, photons: float, t: float) -> float:
        """Noise-free mean of the good pixels' signal [DN] (lit less dark) at one step."""

        def mean(p: float) -> float:
            e = self.qe * p * self.gain + (self.dark_map + self.hot_extra) * t
            y = self.k * self.response(np.minimum(e, self.full_well_e))
            return float(np.mean(y[~self.hot_mask]))

        return mean(photons) - mean(0.0)

    def frames(self, photons: float, t: float, count: int) -> np.ndarray:
        e_mean = self.qe * photons * self.gain + (self.dark_map + self.hot_extra) * t
        out = np.empty((count, *self.shape), np.uint16)
        for i in range(count):
            e = np.minimum(self.rng.poisson(e_mean).astype(np.float64), self.full_well_e)
            noise = self.read_noise_e * self.rng.standard_normal(self.shape)
            y = self.k * (self.response(e) + self.offset_e + noise) + self.black_dn
            out[i] = np.clip(np.rint(y), 0, (1 << self.bits) - 1)
        return out

    def series(self, steps: int = 40, t_max: float = 0.5) -> dict[str, np.ndarray]:
        """The exposure-time series as the arrays of a frames ``.npz``."""
        t = np.linspace(t_max / steps, t_max, steps)
        ph = self.photon_rate * t
        return {
            "exposure_s": t,
            "photons_per_pixel": ph,
            "flats": np.stack([self.frames(p, ti, 2) for p, ti in zip(ph, t, strict=True)]),
            "darks": np.stack([self.frames(0.0, ti, 2) for ti in t]),
            "bits": np.array(self.bits),
        }


def pair_table(series: dict[str, np.ndarray]) -> list[list[float]]:
    """A lab's table from the images (numpy alone, every pixel): per step the dark row and the lit
    row, ``exposure_s, kind (1 = dark), mean, variance`` by EMVA 1288's pair formula."""

    def pair(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        a, b = a.astype(np.float64), b.astype(np.float64)
        d = (a - a.mean()) - (b - b.mean())
        return 0.5 * float(a.mean() + b.mean()), 0.5 * float(np.mean(d * d))

    rows = []
    for t, flat, dark in zip(series["exposure_s"], series["flats"], series["darks"], strict=True):
        rows.append([float(t), 1.0, *pair(*dark)])
        rows.append([float(t), 0.0, *pair(*flat)])
    return rows
