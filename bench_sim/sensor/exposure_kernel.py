"""The exposure loop's per-pixel arithmetic, compiled: the joint shot + read draw's quantile and
the conversion of electrons to raw DN, in one pass over the pixels.

One loop (:data:`LOOPS`) does, per pixel, what :func:`bench_sim.sensor.emva.expose` needs after
its normals are drawn: the third-order Cornish-Fisher quantile of shot + read noise at the
standard normal ``z`` (:func:`joint_quantile`), the conversion of electrons to DN (gain,
offsets, saturation flag, ADC: :func:`electrons_to_dn`), or both at once without storing the
electrons (:func:`joint_draw_dn`, the in-cache loop's common case). Each is the same sequence of
floating-point operations, in the same order and precision, as the numpy expressions it
replaced (no fused multiply-add: numba's default, ``fastmath`` off), so the results are
bit-identical to them; ``tests/sensor/test_exposure_kernel.py`` holds those numpy expressions
and compares bit for bit.

The quantile is evaluated in float32 (the quantised pixel model's working precision); the
conversion to DN in float32 into ``uint16`` (quantisation on) or in float64 into float64
(quantisation off): one compiled signature each. Compiled by
:func:`bench_sim.runtime.jit.compiled` (numba, imported on first use, cached on disk).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench_sim.runtime.jit import compiled

__all__ = ["joint_quantile", "electrons_to_dn", "joint_draw_dn", "LOOPS"]


def _pixel_loop(
    z: Any, mean: Any, var: Any, read_var: Any, lam: Any, e: Any, gain: Any, offset: Any, top: Any,
    limit: Any, rint: bool, out: Any, sat: Any, quantile: bool, to_dn: bool,
) -> None:
    # the loop numba compiles (LOOPS), a line at a time: x = the quantile (quantile) or e, then
    # the DN of x into out and sat (to_dn) or x into e; see the wrappers below for the arguments.
    # Each inner loop has no branch but on loop-invariant flags, so LLVM vectorises it.
    n, cols = z.shape if quantile else e.shape
    zero = top - top  # 0 in the working dtype
    buf = np.empty(cols if to_dn else 0, e.dtype)  # x of a line that is not stored
    flag = np.empty(cols if to_dn else 0, np.bool_)  # its saturation flags
    c_z, c_z0 = np.float32(5 / 36), np.float32(0.125)  # the coefficient of z: (5 a / 36 - 1 / 8) b + s
    c_z3, c_z30 = np.float32(-1 / 18), np.float32(1 / 24)  # of z^3: (1 / 24 - a / 18) b
    c_z2 = np.float32(1 / 6)  # of z^2 (and of the mean's shift): a / 6
    for i in range(n):
        x = buf if to_dn else e[i]
        if quantile:
            zi, mi, vi, li = z[i], mean[i], var[i], lam[i]
            for j in range(cols):
                v = vi[j] + read_var
                s = np.sqrt(v)
                a = np.divide(li[j], v)  # numpy's division: no zero check, vectorised
                b = np.divide(a, s)
                c = a * c_z
                c = c - c_z0
                c = c * b
                c = c + s
                t = a * c_z3
                t = t + c_z30
                t = t * b
                a = a * c_z2
                xj = t * zi[j]
                xj = xj + a
                xj = xj * zi[j]
                xj = xj + c
                xj = xj * zi[j]
                x[j] = xj + (mi[j] - a)
        else:
            x = e[i]
        if not to_dn:
            continue
        oi = out[i]
        for j in range(cols):
            d = x[j] * gain
            d = d + offset[j]
            flag[j] = d >= limit
            if rint:
                d = np.rint(d)
            if d < zero:  # np.clip: -0.0 and NaN pass unchanged
                d = zero
            if d > top:
                d = top
            oi[j] = d
        if sat.shape[0] != 0:
            si = sat[i]
            for j in range(cols):
                si[j] = si[j] | flag[j]


def _signature(f: str, dn: str) -> str:
    # numba's type names: the arrays the loop only reads are typed read-only (writable ones
    # pass too; the fixed pattern's are read-only), the others C-contiguous and writable
    r1, r2 = f'Array({f}, 1, "C", readonly=True)', f'Array({f}, 2, "C", readonly=True)'
    return (f"void({r2}, {r2}, {r2}, {f}, {r2}, {f}[:, ::1], {f}, {r1}, {f}, {f}, boolean, "
            f"{dn}[:, ::1], boolean[:, ::1], boolean, boolean)")


#: float32 pixels, DN as uint16 (quantisation on: every mode)
_SIG32 = _signature("float32", "uint16")
#: float64 pixels, DN as float64 (quantisation off: the conversion to DN only)
_SIG64 = _signature("float64", "float64")

#: the loop and its signatures (:func:`bench_sim.runtime.jit.compiled`, ``warm_up``)
LOOPS = ((_pixel_loop, _SIG32), (_pixel_loop, _SIG64))

_NO_SAT = np.zeros((0, 0), dtype=bool)
_UNUSED: dict[np.dtype, tuple[np.ndarray, np.ndarray, np.ndarray]] = {
    np.dtype(d): (np.zeros((0, 0), d), np.zeros(0, d), np.zeros((0, 0), u))
    for d, u in ((np.float32, np.uint16), (np.float64, np.float64))
}  # the arrays of a mode that does not read them: pixels, offsets, DN


def _loop(dtype: np.dtype) -> Any:
    if dtype not in _UNUSED:
        raise ValueError(f"pixels of dtype {dtype}: float32 or float64")
    return compiled(*LOOPS[0 if dtype == np.float32 else 1])


def _same_shape(shape: tuple[int, ...], **arrays: np.ndarray | None) -> None:
    """Raise unless every array given has ``shape`` (the loop runs without bounds checks)."""
    for name, a in arrays.items():
        if a is not None and a.shape != shape:
            raise ValueError(f"{name}: shape {a.shape}, expected {shape}")


def _as_rows(a: np.ndarray) -> np.ndarray:
    """``a`` as one C-contiguous row (a view where it already is contiguous)."""
    return np.ascontiguousarray(a).reshape(1, -1)


def joint_quantile(
    z: np.ndarray, mean: np.ndarray, var: np.ndarray, lam: np.ndarray, out: np.ndarray,
    read_var: float | np.floating = 0.0,
) -> np.ndarray:
    """Third-order Cornish-Fisher quantile of shot + read noise at the standard normal ``z``
    (mean ``mean``, variance ``var + read_var``, third and fourth cumulants ``lam``), into
    ``out``.

    The expansion of ``bench_sim.sensor.sampler._cornish_fisher(z, mean, v, lam, lam)``,
    ``x = mean + s z + a (z^2 - 1) / 6 + b (z^3 - 3 z) / 24 - c (2 z^3 - 5 z) / 36`` with
    ``s = sqrt(v)``, ``a = lam / v``, ``b = a / s``, ``c = a b``, gathered by powers of ``z``::

        x = (mean - a / 6) + z (s + b (5 a / 36 - 1 / 8)) + z^2 a / 6 + z^3 b (1 / 24 - a / 18)

    (the same polynomial; rounding differs from the plain form in the last bits), evaluated per
    pixel in float32 as ``((t z + a / 6) z + c) z + (mean - a / 6)`` with ``c = (a 5/36 - 1/8) b
    + s`` and ``t = (a (-1/18) + 1/24) b``.

    Parameters
    ----------
    z
        Standard normal numbers (float32).
    mean
        Mean electrons of the sum [e-] (float32; may be ``lam``).
    var
        Its variance [e-^2] (float32; may be ``lam``, plus ``read_var``).
    lam
        Mean electrons of the Poisson part [e-] (float32), its third and fourth cumulants.
    out
        C-contiguous float32 array of ``z``'s shape, overwritten (the others are read only and
        may be any float32 arrays of that shape).
    read_var
        Read-noise variance [e-^2] added to ``var`` (in float32; ``0`` leaves ``var`` as is).

    Returns
    -------
    numpy.ndarray
        ``out``: the quantile [e-].
    """
    _same_shape(z.shape, mean=mean, var=var, lam=lam, out=out)
    if not out.flags.c_contiguous:
        raise ValueError("out: must be C-contiguous")
    x = out.reshape(1, -1)
    _, offsets, dn = _UNUSED[np.dtype(np.float32)]
    zero = np.float32(0.0)
    _loop(np.dtype(np.float32))(_as_rows(z), _as_rows(mean), _as_rows(var), np.float32(read_var),
                                _as_rows(lam), x, zero, offsets, zero, zero, False, dn, _NO_SAT,
                                True, False)
    return out


def _dn_limits(dtype: np.dtype, top: float, quantization: bool) -> tuple[Any, Any]:
    """The ADC's top value and the saturation flag's threshold in ``dtype`` (as numpy compares a
    float32 array with a Python float: in float32)."""
    return dtype.type(top), dtype.type(top - (0.5 if quantization else 0.0))


def electrons_to_dn(
    e: np.ndarray,
    gain: np.floating,
    offset_dn: np.ndarray,
    top: float,
    quantization: bool,
    out: np.ndarray,
    saturated: np.ndarray | None,
) -> None:
    """Electrons -> raw DN (gain, offsets, ADC), stored into ``out``.

    Per pixel in ``e``'s dtype ``dn = e * K + offset``, ``saturated |= dn >= top - 0.5``
    (``>= top`` without quantisation; before the rounding), ``rint(dn)`` (with quantisation),
    ``clip(dn, 0, top)``, then the cast to ``out``'s dtype.

    Parameters
    ----------
    e
        (..., N) electrons [e-]: float32 with quantisation, float64 without (not changed).
    gain
        Conversion gain K [DN/e-], a scalar of ``e``'s dtype.
    offset_dn
        (N,) black plus column offsets [DN], ``e``'s dtype.
    top
        Largest raw value [DN].
    quantization
        Round to integers.
    out
        Where the DN go (``e``'s shape; ``uint16`` for float32 ``e``, float64 for float64).
    saturated
        The saturation mask to update (``e``'s shape), or None.
    """
    _same_shape(e.shape, out=out, saturated=saturated)
    if e.size == 0:
        return
    cols = e.shape[-1]
    o = out if out.flags.c_contiguous else np.empty(out.shape, out.dtype)
    s = None if saturated is None else np.ascontiguousarray(saturated)
    d = e.dtype
    pixels, offsets, _ = _UNUSED[d]
    top_d, limit = _dn_limits(d, top, quantization)
    _loop(d)(pixels, pixels, pixels, d.type(0), pixels, np.ascontiguousarray(e).reshape(-1, cols),
             d.type(gain), np.ascontiguousarray(np.broadcast_to(offset_dn, (cols,)), d), top_d, limit,
             quantization, o.reshape(-1, cols), _NO_SAT if s is None else s.reshape(-1, cols),
             False, True)
    if o is not out:
        out[...] = o
    if saturated is not None and s is not saturated:
        saturated[...] = s


def joint_draw_dn(
    z: np.ndarray, lam: np.ndarray, read_var: np.floating, gain: np.floating, offset_dn: np.ndarray,
    top: float, out: np.ndarray, saturated: np.ndarray | None,
) -> None:
    """The raw DN of the joint shot + read draw at the normals ``z``: :func:`joint_quantile`
    ``(z, lam, lam, lam, read_var)`` then :func:`electrons_to_dn` with quantisation, in one pass
    (the electrons are not stored).

    Parameters
    ----------
    z
        (L, N) standard normal numbers (float32, C-contiguous).
    lam
        (L, N) mean electrons [e-] (float32, C-contiguous): the Poisson mean, shot and dark.
    read_var
        Read-noise variance [e-^2].
    gain
        Conversion gain K [DN/e-].
    offset_dn
        (N,) black plus column offsets [DN] (float32, C-contiguous).
    top
        Largest raw value [DN].
    out
        (L, N) ``uint16`` C-contiguous: the raw values [DN].
    saturated
        (L, N) boolean C-contiguous or None: ``|=`` where the ADC's top was reached.

    Releases the GIL: threads exposing different chunks run in parallel.
    """
    _same_shape(z.shape, lam=lam, out=out, saturated=saturated)
    _same_shape((z.shape[1],), offset_dn=offset_dn)
    f32 = np.dtype(np.float32)
    pixels, _, _ = _UNUSED[f32]
    top_d, limit = _dn_limits(f32, top, True)
    _loop(f32)(z, lam, lam, np.float32(read_var), lam, pixels, np.float32(gain), offset_dn, top_d,
               limit, True, out,
               _NO_SAT if saturated is None else saturated, True, True)
