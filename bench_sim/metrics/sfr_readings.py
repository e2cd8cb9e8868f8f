"""What is read off an SFR curve: MTF50, the SFR at a frequency, MTF50P, the peak and whether the
image was sharpened, and the frequency along the pixel axis instead of the edge normal.

* **MTF50**: the lowest frequency at which the SFR falls to 0.5.
* **MTF50P** (Imatest's name): the lowest frequency, past the peak, at which the SFR falls to half
  its *peak* value below the Nyquist frequency. Without sharpening the peak is the SFR at 0
  (1) and MTF50P = MTF50; a sharpened camera image has an SFR above 1 somewhere and its MTF50 is
  inflated by the sharpening, which MTF50P is not [IMATEST]_.
* **Sharpening** is flagged when that peak exceeds :data:`SHARPENING_PEAK` (an SFR above 1 is
  impossible for a passive optical system and a pixel aperture; an image whose SFR rises that far
  has been sharpened, or its edge is not linear in the light).
* **Frequency axis**: the e-SFR's frequencies run along the edge normal (ISO 12233:2017). A tool
  that reports them along the pixel row (a near-vertical edge) or column (near-horizontal), as
  ISO 12233:2000 and ``sfrmat3`` did, gives ``f cos(theta)`` for the same sample
  (:func:`axis_frequency`): its MTF50 is lower by ``cos(theta)``.

References
----------
.. [IMATEST] Imatest LLC, "Sharpness: What is it and how is it measured?" (MTF50 and MTF50P),
   https://www.imatest.com/docs/sharpness/ .
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "mtf50",
    "mtf_at",
    "mtf50p",
    "sfr_peak",
    "axis_frequency",
    "SHARPENING_PEAK",
    "FREQUENCY_AXES",
]

#: an SFR peak (below Nyquist) above this marks a sharpened image
SHARPENING_PEAK = 1.05
#: the frequency axes a result can be stated on: ``normal`` (the standard) or ``pixel`` (the row
#: or column axis across the edge)
FREQUENCY_AXES = ("normal", "pixel")
_NYQUIST = 0.5


def mtf50(frequency: np.ndarray, sfr: np.ndarray, level: float = 0.5) -> float:
    """Lowest frequency at which ``sfr`` falls to ``level`` (linear interpolation between the
    samples around the first crossing), in the units of ``frequency``; NaN if it never does."""
    f, s = np.asarray(frequency, dtype=np.float64), np.asarray(sfr, dtype=np.float64)
    below = np.nonzero(s <= level)[0]
    if below.size == 0:
        return float("nan")
    k = int(below[0])
    if k == 0:
        return float(f[0])
    s0, s1 = s[k - 1], s[k]
    return float(f[k - 1] + (f[k] - f[k - 1]) * (s0 - level) / (s0 - s1))


def mtf_at(frequency: np.ndarray, sfr: np.ndarray, f: float) -> float:
    """SFR at frequency ``f`` (linear interpolation); NaN outside the sampled range."""
    fr = np.asarray(frequency, dtype=np.float64)
    if f < fr[0] or f > fr[-1]:
        return float("nan")
    return float(np.interp(f, fr, np.asarray(sfr, dtype=np.float64)))


def sfr_peak(frequency_cyc_px: np.ndarray, sfr: np.ndarray) -> tuple[float, float]:
    """``(peak, frequency)``: the largest SFR at frequencies up to Nyquist (0.5 cycles/px) and
    where it lies [cycles/px]."""
    f, s = np.asarray(frequency_cyc_px, dtype=np.float64), np.asarray(sfr, dtype=np.float64)
    keep = f <= _NYQUIST + 1e-12
    k = int(np.argmax(np.where(keep, s, -np.inf)))
    return float(s[k]), float(f[k])


def mtf50p(frequency_cyc_px: np.ndarray, sfr: np.ndarray) -> float:
    """MTF50P [cycles/px]: past the peak below Nyquist (:func:`sfr_peak`), the lowest frequency at
    which the SFR falls to half the peak (module docstring); NaN if it never does."""
    f, s = np.asarray(frequency_cyc_px, dtype=np.float64), np.asarray(sfr, dtype=np.float64)
    peak, at = sfr_peak(f, s)
    k = int(np.searchsorted(f, at))
    return mtf50(f[k:], s[k:], 0.5 * peak)


def axis_frequency(frequency_normal: np.ndarray | float, edge_angle_deg: float) -> np.ndarray:
    """Frequencies along the edge normal restated along the pixel axis across the edge (the rows
    for a near-vertical edge, the columns for a near-horizontal one): ``f cos(theta)``."""
    return np.asarray(frequency_normal, dtype=np.float64) * math.cos(math.radians(edge_angle_deg))
