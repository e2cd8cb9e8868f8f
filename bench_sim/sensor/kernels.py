"""In-place array kernels of the exposure loop (:func:`bench_sim.sensor.emva.expose`).

The pixel model's arithmetic, written as fixed sequences of numpy operations into preallocated
arrays, on slabs of frame lines that stay in the cache: the quantile of the joint shot + read
draw (:func:`joint_quantile_into`, used by every path that makes that draw, so they agree bit for
bit) and the conversion of electrons to raw DN (:func:`electrons_to_dn`, the same operations as
the plain expressions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Scratch", "joint_quantile_into", "electrons_to_dn", "TILE_ELEMENTS"]

#: Elements per slab of the in-cache loops (whole lines of a frame). A slab's ten float32
#: arrays (5 MiB) stay in the L3 cache; smaller slabs lose more to numpy's per-call cost (about
#: 2 us per operation) than they gain from L2, larger ones go out to memory.
TILE_ELEMENTS = 1 << 17


@dataclass(frozen=True)
class Scratch:
    """Scratch arrays of one slab shape and dtype (``v``: a variance; ``s, a, b, c, t``: the
    Cornish-Fisher intermediates; ``x``: the result; ``flag``: a boolean mask)."""

    v: np.ndarray
    s: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    t: np.ndarray
    x: np.ndarray
    flag: np.ndarray

    @classmethod
    def of(cls, shape: tuple[int, ...], dtype: np.dtype) -> Scratch:
        """Uninitialised scratch arrays of ``shape`` and ``dtype``."""
        v, s, a, b, c, t, x = (np.empty(shape, dtype=dtype) for _ in range(7))
        return cls(v, s, a, b, c, t, x, flag=np.empty(shape, dtype=bool))

    def head(self, n: int) -> Scratch:
        """The same arrays cut to their first ``n`` entries along the first axis."""
        return Scratch(self.v[:n], self.s[:n], self.a[:n], self.b[:n], self.c[:n], self.t[:n],
                       self.x[:n], self.flag[:n])


def joint_quantile_into(
    z: np.ndarray, mean: np.ndarray, var: np.ndarray, lam: np.ndarray, w: Scratch
) -> np.ndarray:
    """Third-order Cornish-Fisher quantile of shot + read noise at the standard normal ``z``
    (mean ``mean``, variance ``var``, third and fourth cumulants ``lam``), into ``w.x``.

    The expansion of ``bench_sim.sensor.sampler._cornish_fisher(z, mean, var, lam, lam)``,
    ``x = mean + s z + a (z^2 - 1) / 6 + b (z^3 - 3 z) / 24 - c (2 z^3 - 5 z) / 36`` with
    ``s = sqrt(var)``, ``a = lam / var``, ``b = a / s``, ``c = a b``, gathered by powers of ``z``
    into 18 in-place operations::

        x = (mean - a / 6) + z (s + b (5 a / 36 - 1 / 8)) + z^2 a / 6 + z^3 b (1 / 24 - a / 18)

    (the same polynomial; rounding differs from the plain form in the last bits).

    All arrays share one shape and dtype (float32 or float64). ``w`` is overwritten but for
    ``w.v`` (which may hold ``var``); ``z``, ``mean``, ``var`` and ``lam`` are not (``mean`` and
    ``lam`` may be the same array).

    Returns
    -------
    numpy.ndarray
        ``w.x``: the quantile [e-].
    """
    d = w.x.dtype.type
    s, a, b, c, t, x = w.s, w.a, w.b, w.c, w.t, w.x
    np.sqrt(var, out=s)
    np.divide(lam, var, out=a)
    np.divide(a, s, out=b)
    np.multiply(a, d(5 / 36), out=c)  # c: the coefficient of z
    c -= d(0.125)
    c *= b
    c += s
    np.multiply(a, d(-1 / 18), out=t)  # t: the coefficient of z^3
    t += d(1 / 24)
    t *= b
    a *= d(1 / 6)  # a: the coefficient of z^2
    np.multiply(t, z, out=x)
    x += a
    x *= z
    x += c
    x *= z
    np.subtract(mean, a, out=t)
    x += t
    return x


def electrons_to_dn(
    e: np.ndarray,
    gain: np.floating,
    offset_dn: np.ndarray,
    top: float,
    quantization: bool,
    out: np.ndarray,
    saturated: np.ndarray | None,
    flag: np.ndarray | None = None,
) -> None:
    """Electrons -> raw DN (gain, offsets, ADC), in place in ``e``, stored into ``out``.

    The same operations as ``dn = e * K + offset; rint(dn); clip(dn, 0, top)`` in ``e``'s
    dtype; ``saturated`` (if given) gets ``|= dn >= top - 0.5`` (``>= top`` without
    quantisation) before the rounding.

    Parameters
    ----------
    e
        Electrons [e-], overwritten.
    gain
        Conversion gain K [DN/e-], a scalar of ``e``'s dtype.
    offset_dn
        Black plus column offsets [DN], broadcastable to ``e``.
    top
        Largest raw value [DN].
    quantization
        Round to integers.
    out
        Where the DN go (``e``'s shape; cast to its dtype).
    saturated, flag
        The saturation mask to update and a boolean scratch array of ``e``'s shape.
    """
    e *= gain
    e += offset_dn
    if saturated is not None:
        limit = top - (0.5 if quantization else 0.0)
        if flag is None:
            saturated |= e >= limit
        else:
            np.greater_equal(e, limit, out=flag)
            saturated |= flag
    if quantization:
        np.rint(e, out=e)
    np.clip(e, 0, top, out=e)
    out[...] = e
