"""The fast engine's tap loop, compiled: one sensor row's kernel applied to a chunk of frames.

Tap ``(a, b)`` of column ``n`` at frame ``k`` of the chunk reads the smeared texture's window
texel ``(y0 + a + k q, x0 + b + n q)``, stored in phase plane ``((y0 + a) % q, (x0 + b) % q)``
at row ``(y0 + a) // q + k`` and column ``(x0 + b) // q + n``
(:meth:`bench_sim.render.engines.FastEngine.radiance_frames`). Every output pixel adds its
taps in a fixed order (``a`` outer, ``b`` inner), each as ``acc + fl(texel * weight)`` in
float32 with no fused multiply-add (numba's default, ``fastmath`` off): the same operations, in
the same order, as a numpy loop over the taps of ``np.multiply(plane, weight, out=tmp); acc +=
tmp``, so the results are bit-identical to it.

Compiled by :func:`bench_sim.runtime.jit.compiled` (numba, imported on first use, cached on
disk); :data:`TAP_LOOP` names it for :func:`bench_sim.runtime.jit.warm_up`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench_sim.runtime.jit import compiled

__all__ = ["apply_taps", "TAP_LOOP"]

#: The loop's one signature: C-contiguous float32 arrays, int64 offsets (numba's type names)
_SIGNATURE = "void(float32[:, :, :, ::1], float32[:, :, ::1], int64, int64, float32[:, ::1])"


def _tap_loop(planes: Any, weights: Any, y0: int, x0: int, acc: Any) -> None:
    # the loop numba compiles (TAP_LOOP); see apply_taps for the arguments
    q = planes.shape[0]
    nk, n_cols = acc.shape
    ty, tx = weights.shape[0], weights.shape[1]
    for k in range(nk):
        row = acc[k]
        for a in range(ty):
            ya = y0 + a
            for b in range(tx):
                xb = x0 + b
                prow = planes[ya % q, xb % q, ya // q + k, xb // q : xb // q + n_cols]
                w = weights[a, b]
                for n in range(n_cols):
                    row[n] = row[n] + prow[n] * w[n]


#: the loop and its signature (:func:`bench_sim.runtime.jit.compiled`)
TAP_LOOP = (_tap_loop, _SIGNATURE)


def apply_taps(planes: np.ndarray, weights: np.ndarray, y0: int, x0: int, acc: np.ndarray) -> None:
    """Add one sensor row's kernel applied to a chunk of frames to ``acc``, in place.

    Parameters
    ----------
    planes : numpy.ndarray
        (q, q, R, C) float32, C-contiguous: the phase planes of the smeared texture's window
        (reflectance, unitless); ``planes[i, j, r, c]`` is window texel ``(i + r q, j + c q)``.
        Rows and columns no tap reaches may hold anything.
    weights : numpy.ndarray
        (ty, tx, N) float32, C-contiguous: tap ``(a, b)``'s weight for each column, radiance per
        unit albedo [W m^-2 sr^-1].
    y0, x0 : int
        Window texel row and column of tap ``(0, 0)`` for frame 0 of the chunk and column 0
        (>= 0); frame ``k`` reads ``k q`` texel rows further on, column ``n`` ``n q`` texel
        columns further on.
    acc : numpy.ndarray
        (frames, N) float32, C-contiguous: radiance [W m^-2 sr^-1], added to in place.

    Releases the GIL: threads applying different rows run in parallel.
    """
    compiled(*TAP_LOOP)(planes, weights, y0, x0, acc)
