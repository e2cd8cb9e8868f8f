r"""``Gamma_TRA``: display transforms of the fused HDR image (paper section 2.2, Fig. 4(b)).

The paper only says "a simple gray transformation". The transforms offered here (the names of
``FusionConfig.tra``) are, with ``x`` the HDR value [DN], ``X`` the full scale [DN] (by default
the HDR image's theoretical full scale ``(mu2/mu1) * (2**beta - 1)`` when the caller passes it,
else ``max(x)``), ``y`` the display value in ``0 .. 1``:

``"log"``
    ``y = ln(1 + max(x, 0)) / ln(1 + X)``, clipped to ``0 .. 1``.
``"gamma"``
    ``y = clip(x / X, 0, 1) ** (1 / g)``, ``g = 2.2`` by default.
``"histeq"``
    Histogram equalisation on the exact values (no binning):
    ``y(v) = (C(v) - C(v_min)) / (P - C(v_min))`` with ``C(v)`` the number of pixels with value
    ``<= v``, ``v_min`` the smallest value and ``P`` the number of pixels; ``y = 0`` for a constant
    image. (The same formula as ``cv2.equalizeHist`` for 8-bit data, without its 256 bins.)
``"reinhard"``, ``"drago"``, ``"mantiuk"``
    OpenCV's ``createTonemapReinhard`` (Reinhard et al. 2005), ``createTonemapDrago`` (Drago et
    al. 2003), ``createTonemapMantiuk`` (Mantiuk et al. 2006) with OpenCV's default parameters
    and ``gamma = 2.2``, applied to ``max(x / X, 0.5 / X)`` (a floor of half a DN keeps the
    operators' logarithms finite) as a gray RGB image; NaNs (if any) become 0.

The display image is ``round(y * (2**bits - 1))`` as ``uint8`` (``bits = 8``) or ``uint16``
(``bits = 16``).

References
----------
.. [DTDI] *An HDR Imaging Method With DTDI Technology for Push-Broom Cameras* (the paper
   bench_sim reproduces), section 2.2 and Fig. 4(b) (``Gamma_TRA``).
.. [Reinhard] E. Reinhard and K. Devlin, Dynamic range reduction inspired by photoreceptor
   physiology, IEEE Trans. Visualization and Computer Graphics 11(1), 2005, 13-24.
.. [Drago] F. Drago, K. Myszkowski, T. Annen and N. Chiba, Adaptive logarithmic mapping for
   displaying high contrast scenes, Computer Graphics Forum 22(3), 2003, 419-426.
.. [Mantiuk] R. Mantiuk, K. Myszkowski and H.-P. Seidel, A perceptual framework for contrast
   processing of high dynamic range images, ACM Trans. Applied Perception 3(3), 2006, 286-308.
.. [Gonzalez] R. C. Gonzalez and R. E. Woods, Digital Image Processing, 4th ed., Pearson, 2018,
   section 3.3 (histogram equalisation).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bench_sim.config import ConfigError
from bench_sim.errors import BenchSimError

__all__ = [
    "ToneMapMethod",
    "TONEMAP_METHODS",
    "check_tonemap_method",
    "tone_map",
    "gamma_tra",
    "quantize_display",
    "tra_log",
    "tra_gamma",
    "tra_histeq",
    "tra_opencv",
]

def _full_scale(x: NDArray[np.float64], full_scale_dn: float | None) -> float:
    if full_scale_dn is None:
        top = float(np.max(x)) if x.size else 0.0
        return top if top > 0 else 1.0
    if not (np.isfinite(full_scale_dn) and full_scale_dn > 0):
        raise BenchSimError(f"full_scale_dn = {full_scale_dn}: must be a finite number > 0")
    return float(full_scale_dn)


def _as_hdr(hdr: ArrayLike) -> NDArray[np.float64]:
    x = np.asarray(hdr, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise BenchSimError("HDR image: contains NaN or inf; a display transform needs finite values")
    return x


def tra_log(hdr: ArrayLike, full_scale_dn: float | None = None) -> NDArray[np.float64]:
    """``y = ln(1 + max(x, 0)) / ln(1 + X)`` clipped to ``0 .. 1`` (``x``, ``X`` in DN)."""
    x = _as_hdr(hdr)
    big_x = _full_scale(x, full_scale_dn)
    return np.clip(np.log1p(np.maximum(x, 0.0)) / np.log1p(big_x), 0.0, 1.0)


def tra_gamma(
    hdr: ArrayLike, full_scale_dn: float | None = None, gamma: float = 2.2
) -> NDArray[np.float64]:
    """``y = clip(x / X, 0, 1) ** (1 / gamma)``."""
    if not gamma > 0:
        raise BenchSimError(f"gamma = {gamma}: must be > 0")
    x = _as_hdr(hdr)
    big_x = _full_scale(x, full_scale_dn)
    return np.clip(x / big_x, 0.0, 1.0) ** (1.0 / gamma)


def tra_histeq(hdr: ArrayLike) -> NDArray[np.float64]:
    """Histogram equalisation on exact values: ``y = (C(v) - C(v_min)) / (P - C(v_min))``."""
    x = _as_hdr(hdr)
    if x.size == 0:
        return x.copy()
    values, inverse, counts = np.unique(x.ravel(), return_inverse=True, return_counts=True)
    cdf = np.cumsum(counts)
    c_min = cdf[0]
    p = x.size
    if p == c_min:
        return np.zeros_like(x)
    y = (cdf - c_min) / (p - c_min)
    return y[inverse].reshape(x.shape)


def _quiet_opencv(func: Callable[..., Any], *args: Any) -> Any:
    """Call an OpenCV function with its log level at ERROR (OpenCV 5's Reinhard warns on every
    call about multi-channel MatExpr, which would clutter the CLI's stderr)."""
    import cv2

    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None:
        return func(*args)
    previous = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)
    try:
        return func(*args)
    finally:
        log.setLogLevel(previous)


def tra_opencv(
    hdr: ArrayLike,
    operator: Literal["reinhard", "drago", "mantiuk"],
    full_scale_dn: float | None = None,
    gamma: float = 2.2,
) -> NDArray[np.float64]:
    """OpenCV tone-mapping operator on the normalised HDR image; returns ``y`` in ``0 .. 1``."""
    import cv2

    x = _as_hdr(hdr)
    big_x = _full_scale(x, full_scale_dn)
    if x.ndim != 2:
        raise BenchSimError(f"HDR image: tone-mapping operators need a 2-D image, got shape {x.shape}")
    if x.size == 0:
        return x.copy()
    norm = np.maximum(x / big_x, 0.5 / big_x).astype(np.float32)
    rgb = np.ascontiguousarray(np.repeat(norm[..., None], 3, axis=2))
    op: Any
    if operator == "reinhard":
        op = cv2.createTonemapReinhard(gamma)
    elif operator == "drago":
        op = cv2.createTonemapDrago(gamma)
    elif operator == "mantiuk":
        op = cv2.createTonemapMantiuk(gamma)
    else:
        raise BenchSimError(f"operator = {operator!r}: allowed 'reinhard', 'drago', 'mantiuk'")
    out = np.asarray(_quiet_opencv(op.process, rgb), dtype=np.float64)[..., 0]
    return np.clip(np.nan_to_num(out, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


@dataclass(frozen=True)
class ToneMapMethod:
    """A ``Gamma_TRA`` transform: ``y = function(hdr, full_scale_dn, gamma)`` in ``0 .. 1`` and
    its formula (one line, written into the metadata of the outputs that use it)."""

    function: Callable[[ArrayLike, float | None, float], NDArray[np.float64]]
    formula: str

    def __call__(
        self, hdr: ArrayLike, full_scale_dn: float | None = None, gamma: float = 2.2
    ) -> NDArray[np.float64]:
        return self.function(hdr, full_scale_dn, gamma)


#: The display transforms of ``Gamma_TRA``, name -> transform: the one list of them (the names
#: ``fusion.tra`` and ``bench-sim fuse --tra-method`` take, :func:`tone_map`'s dispatch). Add one
#: here and everything else follows. ``x`` HDR value, ``X`` full scale, ``y`` display value.
TONEMAP_METHODS: dict[str, ToneMapMethod] = {
    "log": ToneMapMethod(lambda x, fs, g: tra_log(x, fs), "y = ln(1 + max(x, 0)) / ln(1 + X)"),
    "gamma": ToneMapMethod(tra_gamma, "y = clip(x / X, 0, 1) ** (1 / 2.2)"),
    "histeq": ToneMapMethod(
        lambda x, fs, g: tra_histeq(x),
        "y = (C(x) - C(x_min)) / (P - C(x_min)), C = cumulative count of exact values",
    ),
    "reinhard": ToneMapMethod(
        lambda x, fs, g: tra_opencv(x, "reinhard", fs, g),
        "OpenCV createTonemapReinhard(gamma=2.2) on max(x / X, 0.5 / X) (Reinhard et al. 2005)",
    ),
    "drago": ToneMapMethod(
        lambda x, fs, g: tra_opencv(x, "drago", fs, g),
        "OpenCV createTonemapDrago(gamma=2.2) on max(x / X, 0.5 / X) (Drago et al. 2003)",
    ),
    "mantiuk": ToneMapMethod(
        lambda x, fs, g: tra_opencv(x, "mantiuk", fs, g),
        "OpenCV createTonemapMantiuk(gamma=2.2) on max(x / X, 0.5 / X) (Mantiuk et al. 2006)",
    ),
}


def check_tonemap_method(method: str, key: str = "fusion.tra") -> None:
    """Refuse a transform name not in :data:`TONEMAP_METHODS`: :class:`~bench_sim.config.ConfigError`
    ``config error: KEY = 'NAME': must be one of log, gamma, ...`` (one line)."""
    if method not in TONEMAP_METHODS:
        raise ConfigError(f"config error: {key} = {method!r}: must be one of {', '.join(TONEMAP_METHODS)}")


def tone_map(
    hdr: ArrayLike,
    method: str = "log",
    *,
    full_scale_dn: float | None = None,
    gamma: float = 2.2,
) -> NDArray[np.float64]:
    """Apply the ``Gamma_TRA`` transform ``method`` (see the module notes); ``y`` in ``0 .. 1``.

    Parameters
    ----------
    hdr
        Fused image [DN], e.g. ``FusionResult.hdr``.
    method
        A name of :data:`TONEMAP_METHODS`.
    full_scale_dn
        ``X`` [DN]; ``None``: the image maximum. Not used by ``"histeq"``.
    gamma
        Exponent of ``"gamma"``; display gamma of the OpenCV operators.
    """
    transform = TONEMAP_METHODS.get(method)
    if transform is None:
        raise BenchSimError(f"tra = {method!r}: allowed {', '.join(TONEMAP_METHODS)}")
    return transform(hdr, full_scale_dn, gamma)


def quantize_display(y: ArrayLike, bits: int = 8) -> NDArray[np.unsignedinteger]:
    """``round(clip(y, 0, 1) * (2**bits - 1))`` as ``uint8`` (8 bits) or ``uint16`` (16 bits)."""
    if bits not in (8, 16):
        raise BenchSimError(f"bits = {bits}: display images are 8 or 16 bit")
    dtype = np.uint8 if bits == 8 else np.uint16
    y_arr = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0)
    return np.round(y_arr * (2**bits - 1)).astype(dtype)


def gamma_tra(
    hdr: ArrayLike,
    method: str = "log",
    *,
    full_scale_dn: float | None = None,
    bits: int = 8,
    gamma: float = 2.2,
) -> NDArray[np.unsignedinteger]:
    """``Gamma_TRA``: the display image of ``hdr`` (8- or 16-bit), see :func:`tone_map`."""
    return quantize_display(tone_map(hdr, method, full_scale_dn=full_scale_dn, gamma=gamma), bits)
