"""The truth's per-read arithmetic, compiled: photons to light, and the linear cumulants of a read.

Two loops, one pass over the reads each, in place of the numpy passes they replace:

* :func:`light_quantities` (:class:`bench_sim.sensor.pass_truth.PassTruth`): per read of a chunk
  the PRNU-weighted photons ``p g`` and the light ``p (QE g)`` [e-], plus the dark electrons
  ``d`` where both go into one Poisson mean (``(p (QE g)) + d``); the float32 photons are
  converted to float64 first, as numpy's ``np.multiply(float32, float64)`` converts them.
* :func:`linear_cumulants` (:func:`bench_sim.sensor.expectation.read_cumulants`): per read
  ``kappa_1 = (K (lam + d)) + o``, ``kappa_2 = K^2 (lam + sigma_r^2)`` (``K^2 sigma_r^2``
  without shot noise) ``+ 1/12`` with rounding, ``kappa_3 = K^3 lam`` (0 without shot noise),
  and whether the read lies within ``c`` sd (plus 1 DN) of a clip: ``(kappa_1 + c sd) + 1 >= top``
  or ``(kappa_1 - c sd) - 1 <= lo``, ``sd`` the square root of ``kappa_2`` before the ``1/12``.

Each element goes through the same float64 operations, in the same order, as the numpy
expressions written in the formulas above (no fused multiply-add: numba's default, ``fastmath``
off; ``sqrt`` and the comparisons are exactly rounded), so the results are bit-identical to them;
``tests/sensor/test_cumulant_kernel.py`` compares them bit for bit. Compiled by
:func:`bench_sim.runtime.jit.compiled` (numba, imported on first use, cached on disk);
:data:`LOOPS` names them for :func:`bench_sim.runtime.jit.warm_up`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench_sim.runtime.jit import compiled

__all__ = ["light_quantities", "linear_cumulants", "LIGHT_LOOP", "LINEAR_LOOP", "LOOPS"]

#: inputs may be read-only (the fixed pattern, broadcast views): numba types them apart from
#: writable arrays, and a writable array converts to the read-only type, not the reverse
_IN_2D = "Array(float64, 2, 'C', readonly=True)"
_IN_PH = "Array(float32, 3, 'C', readonly=True)"
_F64_2D = "float64[:, ::1]"
_F64_3D = "float64[:, :, ::1]"
#: photons (float32), gain, QE gain, dark, add_dark, gain_photons, light
_LIGHT_SIGNATURE = (
    f"void({_IN_PH}, {_IN_2D}, {_IN_2D}, {_IN_2D}, boolean, {_F64_3D}, {_F64_3D})"
)
#: lam, det, off, lo, top, K, K^2, K^3, sigma_r^2, noisy, quantization, 1/12, c, k1, k2, k3, near
_LINEAR_SIGNATURE = (
    f"void({_IN_2D}, {_IN_2D}, {_IN_2D}, {_IN_2D}, {_IN_2D}, float64, float64, float64, float64,"
    f" boolean, boolean, float64, float64, {_F64_2D}, {_F64_2D}, {_F64_2D}, boolean[:, ::1])"
)


def _light_loop(ph: Any, gain: Any, qe_gain: Any, dark: Any, add_dark: bool, gp: Any, light: Any) -> None:
    # the loop numba compiles (LIGHT_LOOP); see light_quantities for the arguments
    n_frames, n_rows, n_cols = gp.shape
    for c in range(n_frames):
        for r in range(n_rows):
            p_row, g_row, q_row, d_row = ph[c, r], gain[r], qe_gain[r], dark[r]
            gp_row, light_row = gp[c, r], light[c, r]
            for j in range(n_cols):
                p = np.float64(p_row[j])
                gp_row[j] = p * g_row[j]
                x = p * q_row[j]
                if add_dark:
                    x = x + d_row[j]
                light_row[j] = x


def _linear_loop(
    lam: Any, det: Any, off: Any, lo: Any, top: Any, k: float, k_sq: float, k_cube: float, rn_sq: float,
    noisy: bool, quantization: bool, q_var: float, sigmas: float, k1: Any, k2: Any, k3: Any, near: Any,
) -> None:
    # the loop numba compiles (LINEAR_LOOP); see linear_cumulants for the arguments. Rows of
    # det, off, lo and top repeat with their period (numpy broadcasting over leading axes).
    n_reads, n_cols = lam.shape
    for i in range(n_reads):
        lam_r, det_r, off_r = lam[i], det[i % det.shape[0]], off[i % off.shape[0]]
        lo_r, top_r = lo[i % lo.shape[0]], top[i % top.shape[0]]
        k1_r, k2_r, k3_r, near_r = k1[i], k2[i], k3[i], near[i]
        for j in range(n_cols):
            x = lam_r[j]
            m1 = k * (x + det_r[j]) + off_r[j]
            if noisy:
                v = x + rn_sq
                m3 = k_cube * x
            else:
                v = rn_sq
                m3 = 0.0
            v = k_sq * v
            sd = sigmas * np.sqrt(v)
            if quantization:
                v = v + q_var
            k1_r[j], k2_r[j], k3_r[j] = m1, v, m3
            near_r[j] = ((m1 + sd) + 1.0 >= top_r[j]) | ((m1 - sd) - 1.0 <= lo_r[j])


#: the loops and their signatures (:func:`bench_sim.runtime.jit.compiled`)
LIGHT_LOOP = (_light_loop, _LIGHT_SIGNATURE)
LINEAR_LOOP = (_linear_loop, _LINEAR_SIGNATURE)
LOOPS = (LIGHT_LOOP, LINEAR_LOOP)


def light_quantities(
    ph: np.ndarray, gain: np.ndarray, qe_gain: np.ndarray, dark: np.ndarray, gain_photons: np.ndarray,
    light: np.ndarray, *, add_dark: bool,
) -> None:
    """Per read of a chunk: the PRNU-weighted photons and the light (plus the dark electrons).

    Parameters
    ----------
    ph : numpy.ndarray
        (C, R0, N) float32, C-contiguous: photons per read of C frames [photons]; only rows
        ``0 .. R - 1`` are read (``R0 >= R``).
    gain, qe_gain, dark : numpy.ndarray
        (R, N) float64, C-contiguous: PRNU gain (unitless), quantum efficiency times PRNU gain
        [e-/photon] and dark electrons [e-] of each pixel.
    gain_photons, light : numpy.ndarray
        (C, R, N) float64, C-contiguous, written: ``p g`` [photons] and ``p (QE g)`` [e-], with
        ``add_dark`` ``(p (QE g)) + d`` [e-] (``p`` the photons converted to float64).
    add_dark : bool
        Whether the dark electrons go into ``light`` (shot and dark noise both on, or both off).

    Releases the GIL: threads can run it on different chunks in parallel.
    """
    if ph.dtype != np.float32:
        raise TypeError(f"light_quantities: photons must be float32, got {ph.dtype}")
    if ph.shape[0] != light.shape[0] or ph.shape[1] < light.shape[1] or ph.shape[2] != light.shape[2]:
        raise ValueError(f"light_quantities: photons {ph.shape} do not cover the reads {light.shape}")
    if not gain.shape == qe_gain.shape == dark.shape == light.shape[1:] == gain_photons.shape[1:]:
        raise ValueError(f"light_quantities: pixel factors {gain.shape} do not match the reads {light.shape}")
    compiled(*LIGHT_LOOP)(ph, gain, qe_gain, dark, bool(add_dark), gain_photons, light)


def _row_cycle(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` broadcast to ``shape`` as (P, n) C-contiguous rows whose row ``i % P`` is row ``i`` of
    the broadcast array seen as (-1, n): the leading axes ``a`` is broadcast over are dropped
    (no copy where the rest is C-contiguous, as for per-pixel, per-column and scalar values)."""
    b = np.broadcast_to(a, shape)
    lead = 0
    while lead < len(shape) - 1 and (b.strides[lead] == 0 or shape[lead] == 1):
        lead += 1
    return np.ascontiguousarray(b[(0,) * lead]).reshape(-1, shape[-1])


def linear_cumulants(
    lam: np.ndarray, det: np.ndarray | float, off: np.ndarray | float, lo: np.ndarray | float,
    top: np.ndarray | float, out: tuple[np.ndarray, np.ndarray, np.ndarray], near: np.ndarray, *,
    gain_dn_per_e: float, read_noise_e: float, noisy: bool, quantization_var_dn2: float | None,
    clip_sigmas: float,
) -> None:
    """The linear cumulants of reads, and which reads lie near a clip.

    Parameters
    ----------
    lam : numpy.ndarray
        Float64, C-contiguous: mean electrons of each read's Poisson part [e-].
    det, off, lo, top
        Broadcastable to ``lam``'s shape (float64): electrons without noise [e-], offset ``b + c``
        [DN], the read's lower clip and its top (``min(hi, K FW + o)``) [DN].
    out : tuple of numpy.ndarray
        ``(kappa_1, kappa_2, kappa_3)``, float64, C-contiguous, ``lam``'s shape, written [DN,
        DN^2, DN^3].
    near : numpy.ndarray
        Bool, C-contiguous, ``lam``'s shape, written: the read's mean is within ``clip_sigmas``
        sd (plus 1 DN) of ``lo`` or ``top``.
    gain_dn_per_e, read_noise_e
        ``K`` [DN/e-] and ``sigma_r`` [e-] (0: off).
    noisy
        Whether ``lam`` is Poisson (else ``kappa_2`` is the read noise's, ``kappa_3 = 0``).
    quantization_var_dn2
        Variance added to ``kappa_2`` by the rounding [DN^2] (not in ``sd``), or None (no rounding).
    clip_sigmas
        How many sd count as near a clip.

    Releases the GIL: threads can run it on different arrays in parallel.
    """
    k1, k2, k3 = out
    lam = np.asarray(lam)
    if not all(a.shape == lam.shape and a.flags.c_contiguous for a in (lam, k1, k2, k3, near)):
        raise ValueError("linear_cumulants: lam, out and near must be C-contiguous of one shape")
    if lam.size == 0:
        return
    shape = lam.shape or (1,)
    rows = [a.reshape(-1, shape[-1]) for a in (lam, k1, k2, k3, near)]
    cyc = [_row_cycle(np.asarray(a, dtype=np.float64), shape) for a in (det, off, lo, top)]
    k, rounded = float(gain_dn_per_e), quantization_var_dn2 is not None
    compiled(*LINEAR_LOOP)(
        rows[0], *cyc, k, k * k, k**3, float(read_noise_e) ** 2, bool(noisy), rounded,
        float(quantization_var_dn2 or 0.0), float(clip_sigmas), *rows[1:],
    )
