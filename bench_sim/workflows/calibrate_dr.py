"""What a calibrated camera gives in DTDI: the dynamic range of stages ``mu1``, ``mu2`` and of the
eq. 11 fusion ``Gamma_HDR``, in closed form and through the chain, with what clips each image
(its pixel, its ADC or the output word) and a warning where the word caps a stage.

Each image's DR (:func:`predict_dr`): *closed form, clip* (saturation where the linear response
meets the clip, :func:`bench_sim.sensor.model.stage_dr_model_db`), *closed form, EMVA* (at the
model's variance maximum, :func:`bench_sim.sensor.saturation.stage_variance_maximum_photons`),
*chain* (measured through the sensor, DTDI and eq. 11 as ``reproduce`` measures it,
:func:`bench_sim.measure.chain_dr.measure_chain_dynamic_range`). ``clips_on``
(:func:`bench_sim.sensor.saturation.stage_clip_kind`) says which clip sets each stage's
saturation (``Gamma_HDR`` saturates with ``Gamma1``).

The word cap (:func:`word_caps`): a stage that clips on the ``beta``-bit word saturates before
its pixels or ADC do; the camera's single-frame DR (its EMVA 1288 DR, stage 1 under an unbounded
word) is what the word takes away from. Each capped stage is reported with its DR, whether that
lies below the single-frame DR, and the narrowest word (up to 32 bits) that removes the cap.
"""

from __future__ import annotations

import math
from typing import Any

from bench_sim.config import BenchConfig, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.measure.chain_dr import measure_chain_dynamic_range
from bench_sim.measure.uniform_field import measurement_pedestal_dn
from bench_sim.sensor.model import stage_dr_model_db, stage_saturation_photons, stage_snr1_photons
from bench_sim.sensor.saturation import stage_clip_kind, stage_variance_maximum_photons
from bench_sim.workflows.reproduce.report import AGREE_DB

__all__ = [
    "predict_dr",
    "parse_stage_pair",
    "word_caps",
    "single_frame_dr_db",
    "CHAIN_COLUMNS",
    "WIDEST_WORD",
]

#: Columns of the whole-chain DR measurement (as ``reproduce``).
CHAIN_COLUMNS = 64
#: The widest output word searched for the one that removes a cap
WIDEST_WORD = 32


def parse_stage_pair(text: str | None, cfg: BenchConfig) -> tuple[int, int]:
    """``--stages mu1,mu2`` (default: the config's ``fusion.mu1``, ``fusion.mu2``)."""
    if text is None:
        return cfg.fusion.mu1, cfg.fusion.mu2
    parts = [p.strip() for p in str(text).split(",")]
    try:
        mu1, mu2 = (int(p) for p in parts)
    except ValueError as exc:
        raise BenchSimError(f"--stages = {text!r}: expected two stages 'mu1,mu2', e.g. 10,80") from exc
    if not 1 <= mu1 < mu2 <= cfg.sensor.rows:
        raise BenchSimError(f"--stages = {text!r}: need 1 <= mu1 < mu2 <= sensor.rows = {cfg.sensor.rows}")
    return mu1, mu2


def _emva_db(cfg: BenchConfig, m: int, beta: int, ped: float) -> float:
    """Closed-form EMVA DR [dB] of stage ``m`` under a ``beta``-bit word with pedestal ``ped``."""
    s, t = cfg.sensor, cfg.timing.t_int_s
    vmax = stage_variance_maximum_photons(
        s, t, m, beta_bits=beta, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
    )
    return 20.0 * math.log10(vmax / stage_snr1_photons(s, t, m))


def single_frame_dr_db(cfg: BenchConfig) -> float:
    """The camera's own DR [dB]: stage 1 (one read) under an unbounded word, EMVA saturation."""
    return _emva_db(cfg, 1, WIDEST_WORD, 0.0)


def _clips(cfg: BenchConfig, m: int, beta: int, ped: float) -> str:
    return stage_clip_kind(
        cfg.sensor, m, beta_bits=beta, subtract_black=cfg.dtdi.subtract_black, pedestal_dn=ped
    )


def word_caps(cfg: BenchConfig, stages: tuple[int, ...], pedestal_dn: float) -> list[dict[str, Any]]:
    """The stages the output word caps (module docstring): per stage its DR [dB], the camera's
    single-frame DR [dB], whether it lies below, and the narrowest word that removes the cap
    (None: none up to :data:`WIDEST_WORD` bits)."""
    beta = cfg.dtdi.beta_bits
    single = single_frame_dr_db(cfg)
    out = []
    for m in stages:
        if _clips(cfg, m, beta, pedestal_dn) != "word":
            continue
        wider = None
        for b in range(beta + 1, WIDEST_WORD + 1):
            cb = with_overrides(cfg, {"dtdi": {"beta_bits": b}}, source="a wider word")
            if _clips(cb, m, b, measurement_pedestal_dn(cb, stages)) != "word":
                wider = b
                break
        dr = _emva_db(cfg, m, beta, pedestal_dn)
        out.append(
            {
                "stage": m,
                "beta_bits": beta,
                "dr_db": dr,
                "single_frame_dr_db": single,
                "below_single_frame": dr < single,
                "word_bits_without_cap": wider,
            }
        )
    return out


def predict_dr(
    cfg: BenchConfig,
    mu1: int,
    mu2: int,
    seed: int,
    *,
    lines: int = 32,
    n_levels: int = 40,
    chain: bool = True,
) -> dict[str, Any]:
    """Predicted DR [dB] of ``Gamma1`` (stage ``mu1``), ``Gamma2`` (``mu2``) and ``Gamma_HDR``
    (module docstring); ``agree``: ``|closed_form_emva - chain| <= AGREE_DB`` (``reproduce``'s
    stated scatter). ``chain`` off: closed forms only."""
    t, s = cfg.timing.t_int_s, cfg.sensor
    ped = measurement_pedestal_dn(cfg, (mu1, mu2))
    beta = cfg.dtdi.beta_bits
    sub = cfg.dtdi.subtract_black
    vmax = {
        m: stage_variance_maximum_photons(s, t, m, beta_bits=beta, subtract_black=sub, pedestal_dn=ped)
        for m in (mu1, mu2)
    }
    clip = {
        m: stage_saturation_photons(s, t, m, beta_bits=beta, subtract_black=sub, pedestal_dn=ped)
        for m in (mu1, mu2)
    }
    snr1 = {m: stage_snr1_photons(s, t, m) for m in (mu1, mu2)}
    emva = {
        "gamma1": 20 * math.log10(vmax[mu1] / snr1[mu1]),
        "gamma2": 20 * math.log10(vmax[mu2] / snr1[mu2]),
        "gamma_hdr": 20 * math.log10(vmax[mu1] / snr1[mu2]),
    }
    closed = {
        "gamma1": stage_dr_model_db(cfg, mu1, ped),
        "gamma2": stage_dr_model_db(cfg, mu2, ped),
        "gamma_hdr": 20 * math.log10(clip[mu1] / snr1[mu2]),
    }
    clips = {"gamma1": _clips(cfg, mu1, beta, ped), "gamma2": _clips(cfg, mu2, beta, ped)}
    clips["gamma_hdr"] = clips["gamma1"]
    measured = (
        measure_chain_dynamic_range(
            cfg, seed, mu1=mu1, mu2=mu2, lines=lines, columns=min(CHAIN_COLUMNS, s.columns), n_levels=n_levels
        )
        if chain
        else None
    )
    out: dict[str, Any] = {
        "mu1": mu1,
        "mu2": mu2,
        "pedestal_dn": ped,
        "configured_pedestal_dn": cfg.dtdi.pedestal_dn,
        "beta_bits": beta,
        "agree_db": AGREE_DB,
        "images": {},
        "single_frame_dr_db": single_frame_dr_db(cfg),
        "word_caps": word_caps(cfg, (mu1, mu2), ped),
    }
    for name in ("gamma1", "gamma2", "gamma_hdr"):
        img = None if measured is None else measured.images[name]
        out["images"][name] = {
            "closed_form_clip_db": closed[name],
            "closed_form_emva_db": emva[name],
            "clips_on": clips[name],
            "chain_db": None if img is None else img.dr_db,
            "chain_extrapolated_db": None if img is None else img.dr_db_extrapolated,
            "agree": None if img is None else abs(emva[name] - img.dr_db) <= AGREE_DB,
        }
    out["saturation_photons_per_frame"] = {
        str(m): {"variance_maximum": vmax[m], "clip": clip[m]} for m in vmax
    }
    out["snr1_photons_per_frame"] = {str(m): v for m, v in snr1.items()}
    return out
