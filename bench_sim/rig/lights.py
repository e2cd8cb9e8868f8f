"""Time behaviour of the bench's lights: the relative intensity each light has in each frame.

The scene is linear in each light (:func:`bench_sim.rig.scene.light_names`): a frame's radiance
is the sum over the lights of the radiance under that light alone times the light's mean
relative intensity over the frame's integration window ``[k T, k T + t_int]`` (``T`` the line
period). Steady lights have weight 1 in every frame.
"""

from __future__ import annotations

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig.scene import light_names

__all__ = ["frame_weights"]


def frame_weights(cfg: BenchConfig, name: str, k0: int, k1: int) -> np.ndarray:
    """Mean relative intensity of light ``name`` over the integration window of frames
    ``k0 .. k1 - 1`` (dimensionless, float64, shape ``(k1 - k0,)``; 1 for a steady light)."""
    if name not in light_names(cfg):
        raise ValueError(f"light {name!r}: not among this bench's emitting lights {list(light_names(cfg))}")
    if k1 < k0:
        raise ValueError(f"frames {k0}..{k1}: k1 must not be below k0")
    return np.ones(int(k1) - int(k0), dtype=np.float64)
