"""Training targets of a dataset sample: the noise-free fused image, the per-pixel noise, the camera.

- :func:`expected_gamma_hdr` -> ``gamma_hdr_truth``: the paper's eq. 11 fusion applied to the
  exact expectations of the two fused stage words (``mean_dn`` of stages ``mu1`` and ``mu2``,
  each clipped to the word ``0 .. 2**beta - 1`` as the words are), in the units and with the
  pedestal convention of ``gamma_hdr`` (stage-``mu2`` DN, pedestal removed). It is the image a
  fusion network is trained towards: ``E[gamma_hdr]`` wherever the stage-``mu1`` signal is more
  than a few noise standard deviations from the eq. 11 threshold (elsewhere the noisy decision
  itself is random and ``E[gamma_hdr]`` mixes both branches).
- :func:`fixed_camera` -> one physical sensor (fixed patterns) for every sample of a dataset
  with ``camera = "fixed"``, drawn from its own stream of the dataset's root seed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.fusion.paper import fuse_dtdi_hdr_eq11
from bench_sim.io.strict_json import strict_json
from bench_sim.sensor.emva import FixedPattern, draw_fixed_pattern
from bench_sim.sensor.model import word_clip_dn

__all__ = [
    "CAMERA_SPAWN_KEY",
    "CAMERAS",
    "EXTRA_STAGE_VARIABLES",
    "EXTRA_FUSED_VARIABLES",
    "expected_gamma_hdr",
    "fixed_camera",
    "strict_json",
    "check_camera",
    "training_targets",
    "recorded_values",
]

#: ``camera`` values of a dataset spec: a new physical sensor per sample, or one for all.
CAMERAS: dict[str, str] = {
    "per_sample": "every sample draws its own physical sensor (fixed patterns) from its stream",
    "fixed": "one physical sensor for every sample, drawn from SeedSequence(seed, spawn_key=(2**32,))",
}
#: Spawn key of the fixed camera's stream: above every sample index (samples <= 10**9), so it
#: never coincides with a sample's stream ``SeedSequence(seed, spawn_key=(i,))``.
CAMERA_SPAWN_KEY = 2**32

#: Dataset-only variables (name -> dtype, units, long name) beside the pass's variables (none per
#: stage: ``noise_std_dn`` is the pass's own truth)
EXTRA_STAGE_VARIABLES: dict[str, tuple[str, str, str]] = {}
EXTRA_FUSED_VARIABLES: dict[str, tuple[str, str, str]] = {
    "gamma_hdr_truth": ("float32", "DN", "noise-free Gamma_HDR: eq. 11 of the expected stage words "
                        "(mean_dn of mu1, mu2 clipped to the word), stage-mu2 units, pedestal removed"),
}


def expected_gamma_hdr(
    mean_dn_mu1: np.ndarray, mean_dn_mu2: np.ndarray, *, mu1: int, mu2: int, beta: int, pedestal_dn: float
) -> np.ndarray:
    """Noise-free ``Gamma_HDR`` [DN, stage-``mu2`` units, pedestal removed] (float32).

    ``gamma_i = clip(E[Gamma_mu_i], 0, 2**beta - 1)`` (the expectation of each word clipped as
    the word is), then eq. 11 with the pedestal ``P`` removed: ``(mu2/mu1) (gamma_1 - P)`` where
    ``(gamma_1 - P) mu2 > (2**beta - P) mu1``, else ``gamma_2 - P``.

    Parameters
    ----------
    mean_dn_mu1, mean_dn_mu2
        Exact expectations of the stage words before they clip [DN] (``mean_dn``).
    mu1, mu2
        The fused stages.
    beta
        Word length [bits].
    pedestal_dn
        The pedestal ``P`` both words carry (``dtdi.pedestal_dn``) [DN].

    References
    ----------
    The DTDI HDR fusion rule (eq. 11, with eq. 5, 8, 10) as implemented by
    :func:`bench_sim.fusion.paper.fuse_dtdi_hdr_eq11`.
    """
    top = float(word_clip_dn(beta))
    g1 = np.clip(np.asarray(mean_dn_mu1, dtype=np.float64), 0.0, top)
    g2 = np.clip(np.asarray(mean_dn_mu2, dtype=np.float64), 0.0, top)
    fused = fuse_dtdi_hdr_eq11(g1, g2, mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=float(pedestal_dn))
    return np.asarray(fused.hdr, dtype=np.float32)


def fixed_camera(cfg: BenchConfig, seed: int) -> FixedPattern:
    """The one physical sensor of a ``camera = "fixed"`` dataset of root seed ``seed``: its
    fixed patterns drawn from ``SeedSequence(seed, spawn_key=(CAMERA_SPAWN_KEY,))`` for the
    bench's sensor (the same for every sample, as the sensor keys are not randomised)."""
    stream = np.random.SeedSequence(int(seed), spawn_key=(CAMERA_SPAWN_KEY,))
    return draw_fixed_pattern(cfg.sensor, np.random.default_rng(stream))


def training_targets(ds: Any, cfg: BenchConfig) -> dict[str, np.ndarray]:
    """``gamma_hdr_truth``, when the pass fused two stages, of a pass's dataset
    (:func:`bench_sim.pipeline.run_pass` with its truth)."""
    out: dict[str, np.ndarray] = {}
    if "gamma_hdr" in ds:
        mu1, mu2 = int(ds.attrs["mu1"]), int(ds.attrs["mu2"])
        out["gamma_hdr_truth"] = expected_gamma_hdr(
            ds.mean_dn.sel(stage=mu1).values, ds.mean_dn.sel(stage=mu2).values, mu1=mu1, mu2=mu2,
            beta=int(ds.attrs["beta_bits"]), pedestal_dn=float(ds.attrs["pedestal_dn"]),
        )
    return out


def recorded_values(values: Mapping[str, Any], base_layout: str) -> dict[str, Any]:
    """A sample's drawn values as recorded: ``target.image`` is ``None`` when the sample's
    target layout (drawn, or the base's) uses no image (it was drawn, so the streams are
    unchanged, but does not describe the sample)."""
    out = dict(values)
    if "target.image" in out and out.get("target.layout", base_layout) != "image":
        out["target.image"] = None
    return out


def check_camera(camera: str, randomize: Mapping[str, Any], where: str) -> None:
    """Refuse a ``camera = "fixed"`` spec that randomises a ``sensor.*`` key (one line)."""
    keys = [k for k in randomize if k.startswith("sensor.")]
    if camera == "fixed" and keys:
        raise BenchSimError(
            f"{where}: randomize.{keys[0]}: camera = 'fixed' is one physical sensor for every sample; "
            "randomise no sensor.* key with it (or use camera = 'per_sample')"
        )
