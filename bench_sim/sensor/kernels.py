"""The joint shot + read draw's quantile as :func:`bench_sim.sensor.sampler.shot_and_read_electrons`
calls it: into the result array of a :class:`Scratch`.

The arithmetic is :func:`bench_sim.sensor.exposure_kernel.joint_quantile` (compiled, the same
loop as the exposure loop's, so every path that makes this draw agrees bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench_sim.sensor.exposure_kernel import joint_quantile

__all__ = ["Scratch", "joint_quantile_into"]


@dataclass(frozen=True)
class Scratch:
    """Where :func:`joint_quantile_into` puts its result: ``x``, a C-contiguous float32 array."""

    x: np.ndarray

    @classmethod
    def of(cls, shape: tuple[int, ...], dtype: np.dtype) -> Scratch:
        """An uninitialised result array of ``shape`` and ``dtype``."""
        return cls(np.empty(shape, dtype=dtype))


def joint_quantile_into(
    z: np.ndarray, mean: np.ndarray, var: np.ndarray, lam: np.ndarray, w: Scratch
) -> np.ndarray:
    """Third-order Cornish-Fisher quantile of shot + read noise at the standard normal ``z``
    (mean ``mean`` [e-], variance ``var`` [e-^2], third and fourth cumulants ``lam`` [e-]), into
    ``w.x``: :func:`bench_sim.sensor.exposure_kernel.joint_quantile` (float32 arrays of one shape).

    Returns
    -------
    numpy.ndarray
        ``w.x``: the quantile [e-].
    """
    return joint_quantile(z, mean, var, lam, w.x)
