"""The generic draw of a chain with effects: every read through the signal path step by step.

The default chain keeps the compiled fast path of :func:`bench_sim.sensor.emva.expose`; a chain
whose effects act on the reads themselves (a response, row noise, telegraph or stuck pixels, an
offset pattern, a plug-in: :attr:`bench_sim.sensor.effects.chain.SensorChain.temporal`) is drawn
here, in float64, per block of frames (:mod:`bench_sim.sensor.effects.base` for the path):

1. mean electrons ``lam = mu_p QE g`` and dark electrons ``d = I_d t_int`` (the fixed maps);
2. shot noise (:func:`bench_sim.sensor.sampler.shot_electrons`, the sensor's sampler) of the
   Poisson part, the full-well clip (``saturated`` where it is reached);
3. the ``charge`` effects, in order;
4. ``y = K e + o`` with the per-pixel offsets ``o`` (black, column, offset pattern), plus the
   read noise ``K sigma_r eps`` (one normal per read from the chunk's generator);
5. the ``analog`` effects, in order; ``saturated`` where ``y`` reaches the ADC's top (less half
   a DN with rounding);
6. the ADC: ``clip(rint(y), 0, T)`` (no rounding with ``quantization`` off);
7. the ``digital`` effects, in order.

Random numbers: the chunk's generator draws steps 2 and 4 (in that order per block); effect
``j`` draws from child ``j`` of it (:meth:`numpy.random.Generator.spawn`), so the same config
and seed give the same reads with any number of threads or workers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench_sim.config import SensorConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.base import Effect, State, check_block
from bench_sim.sensor.effects.chain import SensorChain, sensor_chain
from bench_sim.sensor.fixed_pattern import FixedPattern
from bench_sim.sensor.sampler import shot_electrons

__all__ = ["GenericPlan", "expose_generic", "needs_generic_path"]


def needs_generic_path(chain: SensorChain, fixed: FixedPattern) -> bool:
    """Whether ``chain`` on the sensor ``fixed`` must be drawn here: an effect acts on the reads
    or the offsets vary per pixel (the fast path's offsets are per column)."""
    return chain.temporal or fixed.offset_dn is not None


@dataclass(frozen=True)
class GenericPlan:
    """What :func:`expose_generic` computes once per sensor, fixed pattern and integration time.

    Attributes
    ----------
    chain
        The effects, with ``states`` their fixed patterns (by name, windowed to the frames).
    qe_gain, dark_e, offset_dn
        (M, N) float64 maps: QE times gain [e-/photon], dark electrons per read [e-], all
        offsets [DN].
    """

    chain: SensorChain
    states: dict[str, State]
    qe_gain: np.ndarray
    dark_e: np.ndarray
    offset_dn: np.ndarray
    gain_dn_per_e: float
    full_well_e: float
    read_e: float
    top_dn: float
    shot_noise: bool
    dark_noise: bool
    quantization: bool
    sampler: str
    digital: bool
    stuck: np.ndarray | None

    @classmethod
    def of(cls, sensor: SensorConfig, fixed: FixedPattern, t_int_s: float) -> GenericPlan:
        """The plan of ``sensor`` on its physical sensor ``fixed`` (the frames' ``M x N``)."""
        offset = sensor.black_offset_dn + np.broadcast_to(fixed.column_offset_dn, fixed.shape)
        if fixed.offset_dn is not None:
            offset = offset + fixed.offset_dn
        chain, states = sensor_chain(sensor), dict(fixed.effects)
        stuck = chain.law(states).stuck
        return cls(
            chain=chain,
            states=states,
            qe_gain=sensor.quantum_efficiency * fixed.prnu_gain,
            dark_e=fixed.dark_current_e_s * float(t_int_s),
            offset_dn=np.ascontiguousarray(offset, dtype=np.float64),
            gain_dn_per_e=float(sensor.conversion_gain_dn_per_e),
            full_well_e=float(sensor.full_well_e),
            read_e=float(sensor.read_noise_e) if sensor.read_noise else 0.0,
            top_dn=float(sensor.pixel_saturation_dn),
            shot_noise=sensor.shot_noise,
            dark_noise=sensor.dark_noise,
            quantization=sensor.quantization,
            sampler=getattr(sensor, "shot_noise_sampler", "hybrid"),
            digital=any(type(e).digital is not Effect.digital for e in chain.effects),
            stuck=None if stuck is None else np.asarray(stuck.mask, dtype=bool),
        )


def _electrons(plan: GenericPlan, ph: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Step 2 without the clip: the electrons of a block of frames of mean photons ``ph``."""
    light = ph * plan.qe_gain  # float64
    if plan.shot_noise and plan.dark_noise:
        return shot_electrons(light + plan.dark_e, rng, plan.sampler)
    if plan.shot_noise:
        return shot_electrons(light, rng, plan.sampler) + plan.dark_e
    if plan.dark_noise:
        return shot_electrons(np.broadcast_to(plan.dark_e, ph.shape).copy(), rng, plan.sampler) + light
    return light + plan.dark_e


def _apply(plan: GenericPlan, hook: str, x: np.ndarray, rngs: list[np.random.Generator]) -> np.ndarray:
    """Every effect's ``hook`` (``charge``, ``analog`` or ``digital``) on the block ``x``."""
    for eff, rng in zip(plan.chain.effects, rngs, strict=True):
        out = getattr(eff, hook)(x, plan.states[eff.name], rng)
        if out is not x:
            x = check_block(out, x.shape, f"sensor.effects.{eff.name} ({eff.kind}, {hook})", hook == "charge")
    return x


def expose_generic(
    plan: GenericPlan,
    frames: np.ndarray,
    rng: np.random.Generator,
    out: np.ndarray,
    sat: np.ndarray | None,
    step: int,
) -> None:
    """Expose ``frames`` (F, M, N) of mean photons through the chain (module docstring) into
    ``out`` (uint16 with quantisation, else float64), ``sat`` (if given) set where a read hit the
    full well or the ADC's top."""
    rngs = rng.spawn(len(plan.chain.effects))
    limit = plan.top_dn - 0.5 if plan.quantization else plan.top_dn
    for f0 in range(0, frames.shape[0], step):
        ph = np.asarray(frames[f0 : f0 + step], dtype=np.float64)
        if not (ph.min() >= 0.0 and np.isfinite(ph.max())):
            raise BenchSimError("photons: must be finite and >= 0 (mean photons per pixel per frame)")
        e = _electrons(plan, ph, rng)
        s = e >= plan.full_well_e
        e = _apply(plan, "charge", np.minimum(e, plan.full_well_e), rngs)
        y = e * plan.gain_dn_per_e + plan.offset_dn
        if plan.read_e > 0:
            y += rng.standard_normal(y.shape) * (plan.gain_dn_per_e * plan.read_e)
        y = _apply(plan, "analog", y, rngs)
        s |= y >= limit
        v = np.clip(np.rint(y) if plan.quantization else y, 0.0, plan.top_dn)
        if plan.digital:
            v = _apply(plan, "digital", v, rngs)
            v = np.clip(np.rint(v) if plan.quantization else v, 0.0, plan.top_dn)
        if plan.stuck is not None:
            s[:, plan.stuck] = False  # a stuck read is a defect, not a clip
        out[f0 : f0 + step] = v
        if sat is not None:
            sat[f0 : f0 + step] = s
