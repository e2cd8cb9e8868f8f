"""The lens applied to the run's texture: the target as the camera sees it, blurred by the lens'
OTF (:func:`bench_sim.rig.lens_psf.lens_otf`) before the engines read it.

The texture grid (:mod:`bench_sim.render.texture`) is the target on the drum, ``q`` texels per
object pixel; one texel is ``h m`` on the sensor (``h`` its size on the drum, ``m`` the
magnification). The lens blurs the image on the sensor, which for a target that is lit evenly
over the PSF's few pixels is the texture blurred by the PSF scaled back to the drum; the
engines then integrate it over each pixel (:mod:`bench_sim.render.engines`) and the sensor
samples it. Each block of texture rows (:data:`bench_sim.render.texture.BLOCK_ROWS`) is blurred
with :attr:`TextureLens.margin_rows` real rows of the target either side (mirrored beyond the
grid's ends) and its columns mirrored by :attr:`TextureLens.margin_cols`, in the Fourier domain
(``rfft2``, the OTF at the block's frequencies, ``irfft2``, in double precision, so that a
uniform target comes back uniform to the bit of its float32 texels): a block's values do not
depend on which pass or chunk asked for it. The drum's curvature changes the scale by under 0.1 % over the
default sensor's rows and is not followed; nor is a light that changes over the PSF (a spot's
edge over a few pixels).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig.geometry import RigGeometry
from bench_sim.rig.lens_psf import LensOTF, lens_otf

__all__ = ["TextureLens", "texture_lens"]


@dataclass(frozen=True, eq=False)
class TextureLens:
    """The lens on a texture grid of texel size ``h_y_m`` x ``h_x_m`` on the sensor [m]."""

    otf: LensOTF
    h_y_m: float
    h_x_m: float
    margin_rows: int
    margin_cols: int
    _cache: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def key(self) -> str:
        """What makes the blur of a grid, as text (the texture's shared blocks)."""
        return f"{self.otf.key}|{self.h_y_m:.9g}|{self.h_x_m:.9g}|{self.margin_rows}|{self.margin_cols}"

    @property
    def exact_key(self) -> str:
        """:attr:`key` and a digest of the OTF on a probe grid of 64 x 64 frequencies: what makes the
        blur to the bit (the on-disk texture store, :mod:`bench_sim.render.texture_store`; the
        key's text rounds the lens' numbers and does not name a spectrum's weights)."""
        probe = self._transfer((64, 64))
        return f"{self.key}|{hashlib.sha256(np.ascontiguousarray(probe).tobytes()).hexdigest()}"

    def _transfer(self, shape: tuple[int, int]) -> np.ndarray:
        got = self._cache.get(shape)
        if got is None:  # numpy's frequencies (scipy.fft's are these): no scipy import for the key
            fy = np.fft.fftfreq(shape[0], d=self.h_y_m)
            fx = np.fft.rfftfreq(shape[1], d=self.h_x_m)
            got = self.otf.grid(fy, fx)
            self._cache[shape] = got
        return got

    def apply(self, raw: np.ndarray, pad_top: int, pad_bottom: int) -> np.ndarray:
        """``raw`` (texture rows, all columns) blurred: ``pad_top`` / ``pad_bottom`` of its rows'
        margins missing (beyond the grid) are mirrored in; returns the rows after the first
        ``margin_rows - pad_top`` and before the last ``margin_rows - pad_bottom``, float32."""
        from scipy import fft

        r, c = self.margin_rows, self.margin_cols
        a = np.pad(np.asarray(raw, dtype=np.float64), ((pad_top, pad_bottom), (c, c)), mode="symmetric")
        spec = fft.rfft2(a, workers=1)  # double precision: an even target stays even to the bit
        spec *= self._transfer(a.shape)
        out = fft.irfft2(spec, s=a.shape, workers=1)
        return np.ascontiguousarray(out[r : a.shape[0] - r, c : a.shape[1] - c], dtype=np.float32)


def texture_lens(cfg: BenchConfig, geom: RigGeometry, h_y_m: float, h_x_m: float) -> TextureLens | None:
    """The bench's lens on a texture of texels ``h_y_m`` x ``h_x_m`` on the drum [m]; ``None`` for
    a perfect lens."""
    otf = lens_otf(cfg)
    if otf is None:
        return None
    hy, hx = h_y_m * geom.magnification, h_x_m * geom.magnification
    return TextureLens(otf, hy, hx, math.ceil(otf.radius_m / hy), math.ceil(otf.radius_m / hx))
