"""Every candidate fusion of one all-stage pass scored against its exact truth (``bench-sim design``).

A candidate is a set of stages of the pass (a pair ``mu1 < mu2``, or a triple ``mu1 < mu_mid <
mu2``), a fusion rule of :data:`bench_sim.measure.fusion_scores.RULES` (``eq11`` fuses pairs only;
the clip-aware rules fuse two or three stages) and an output word of ``beta`` bits. One pass at
the widest word (:attr:`CandidateSpace.pass_beta`) gives them all:

- **words.** A stage word is ``clip(rint(sum + P), 0, 2**beta - 1)``, so the word of a narrower
  ``beta'`` is ``min(word, 2**beta' - 1)`` exactly; the truth's ``clipped`` of the narrower word
  is ``clipped or word >= 2**beta' - 1`` exactly (a read that clipped, or the narrower word at
  its top). The clearance of the clips (:func:`bench_sim.metrics.fusion_truth.clear_of_clips`,
  exact at the pass's word) adds, at a narrower word, that the word's expectation ``mean_dn``
  lies :data:`~bench_sim.metrics.fusion_truth.CLIP_MARGIN_SIGMAS` standard deviations
  (``noise_std_dn``) below its top: the normal law of the word near that clip. Each word's eq.
  11 threshold, saturation levels and offsets are its own (``dtdi.beta_bits = beta'``);
- **the truth.** Per candidate, the fused image of the stage signals (words less their offsets,
  :func:`bench_sim.fusion.stage_pair.stage_offsets_dn`) against the true HDR target of its top
  stage (:func:`bench_sim.fusion.stage_pair.true_hdr_dn`: ``linear_dn`` less the offset):
  bias and RMS of the relative error per region of
  :data:`~bench_sim.metrics.fusion_truth.TRUTH_REGIONS` (the ``spot_edge`` of a triple is that of
  its lowest and highest stage), the share of pixels taken from a stage that clipped there
  (the truth's ``clipped``), the share taken from the lowest stage, and the temporal SNR of the
  darkest region (:data:`DARK_FRACTION` of the pixels with the least light per row at the pass's
  highest stage; :func:`bench_sim.measure.pass_metrics.stage_temporal_var_dn2` of the stage each
  pixel came from): all from one compiled pass over the pixels per top stage
  (:func:`bench_sim.metrics.fusion_sums.fusion_sums`);
- **closed forms.** The dynamic range of the fused image (:func:`bench_sim.sensor.model.hdr_dr_model_db`)
  and what the word takes from it (the same with a word that never clips, less it).

:func:`score_candidates` returns one row per candidate (:class:`PassScores`); the rows are
independent of the thread count (each candidate's sums run on one thread, pixel by pixel).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig, with_overrides
from bench_sim.errors import BenchSimError
from bench_sim.fusion.stage_pair import stage_offsets_dn
from bench_sim.measure.fusion_scores import RULES, clip_margin_dn
from bench_sim.measure.pass_metrics import stage_temporal_var_dn2
from bench_sim.metrics.fusion_sums import FIELDS, REGIONS, RULE_EQ11, RULE_SAT, fusion_sums
from bench_sim.metrics.fusion_truth import (
    CLIP_MARGIN_SIGMAS,
    LIGHT_RATIO_TOLERANCE,
    clear_of_clips,
    light_regions,
)
from bench_sim.runtime.parallel import parallel_map
from bench_sim.sensor.model import full_scale_dn, hdr_dr_model_db, word_clip_dn

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "CandidateSpace",
    "PassScores",
    "score_candidates",
    "DARK_FRACTION",
    "SCORE_COLUMNS",
    "word_config",
]

#: the darkest region: this fraction of the pixels, those with the least light per row
DARK_FRACTION = 0.05
#: rule -> the code of :func:`bench_sim.metrics.fusion_sums.fusion_sums`
_CODES = {"eq11": RULE_EQ11, "clip": RULE_SAT, "clip_margin": RULE_SAT}
#: the score columns of a candidate: name -> (units, meaning)
SCORE_COLUMNS: dict[str, tuple[str, str]] = {
    "dr_db": (
        "dB",
        "DR of Gamma_HDR in closed form: 20 lg(saturation of the lowest stage / SNR = 1 of the "
        "highest), photons per pixel per frame",
    ),
    "dr_cap_db": ("dB", "DR the output word takes: the closed form with a word that never clips less dr_db"),
    "truth_bias": ("1", "mean relative error against the true HDR target, whole image"),
    "truth_rms": ("1", "RMS relative error against the true HDR target, whole image"),
    **{
        f"truth_{s}_{r}": (
            "1",
            f"{'mean' if s == 'bias' else 'RMS'} relative error against the true HDR target, region {r!r}",
        )
        for r in REGIONS[1:]
        for s in ("bias", "rms")
    },
    **{f"pixels_{r}": ("1", f"pixels of region {r!r} with a defined error (truth >= 1 DN)") for r in REGIONS},
    "clipped_share": ("1", "share of the pixels taken from a stage that clipped there (the truth's clipped)"),
    "low_share": ("1", "share of the pixels taken from the lowest stage"),
    "snr_dark": (
        "1",
        "temporal SNR of the darkest region of the fused image (model variance of the stage "
        "each pixel came from)",
    ),
}


@dataclass(frozen=True)
class CandidateSpace:
    """The candidates of one pass: stage pairs and triples, rules, output words (ascending)."""

    pairs: tuple[tuple[int, int], ...]
    triples: tuple[tuple[int, int, int], ...]
    rules: tuple[str, ...]
    words: tuple[int, ...]

    @property
    def stages(self) -> tuple[int, ...]:
        """Every stage a candidate uses, ascending."""
        return tuple(sorted({m for c in (*self.pairs, *self.triples) for m in c}))

    @property
    def pass_beta(self) -> int:
        """The word of the pass: the widest candidate word."""
        return max(self.words)

    def rows(self) -> list[tuple[int, str, int, int, int]]:
        """``(beta, rule, mu1, mu_mid, mu2)`` of every candidate (``mu_mid = 0``: a pair), in row
        order: words ascending, rules as given, pairs then triples, each sorted; ``eq11`` fuses
        pairs only."""
        out = []
        for beta, rule in itertools.product(self.words, self.rules):
            out += [(beta, rule, a, 0, b) for a, b in sorted(self.pairs)]
            if rule != "eq11":
                out += [(beta, rule, a, m, b) for a, m, b in sorted(self.triples)]
        return out


@dataclass(frozen=True)
class PassScores:
    """What :func:`score_candidates` returns: one row per candidate (:meth:`CandidateSpace.rows`).

    Attributes
    ----------
    columns
        ``beta_bits``, ``rule``, ``mu1``, ``mu_mid``, ``mu2`` and :data:`SCORE_COLUMNS`, each a
        1-D array over the candidates.
    dark_pixels
        Pixels of the darkest region.
    """

    columns: dict[str, np.ndarray] = field(repr=False)
    dark_pixels: int = 0

    def __len__(self) -> int:
        return int(self.columns["mu1"].size)


def word_config(cfg: BenchConfig, beta: int) -> BenchConfig:
    """The bench ``cfg`` with an output word of ``beta`` bits."""
    return cfg if cfg.dtdi.beta_bits == beta else with_overrides(cfg, {"dtdi": {"beta_bits": int(beta)}})


@dataclass
class _Stacks:
    """(stages, pixels) arrays of the pass at the stages of a space (row ``i``: stage ``stages[i]``)."""

    stages: np.ndarray
    off: np.ndarray
    dn: np.ndarray
    truth: np.ndarray
    valid: np.ndarray
    clipped: np.ndarray
    clear: np.ndarray
    mean: np.ndarray
    noise: np.ndarray
    per_row: np.ndarray
    spot: np.ndarray
    fill: np.ndarray
    dark: np.ndarray
    dark_var: np.ndarray


def _stacks(cfg: BenchConfig, ds: xr.Dataset, stages: Sequence[int]) -> _Stacks:
    """The pass's arrays at all its stages (``stages`` among them), flat over the pixels, and the
    darkest region (by the light per row at the pass's highest stage: the same for every
    candidate)."""
    have = [int(m) for m in ds.stage.values]
    missing = sorted(set(stages) - set(have))
    if missing:
        raise BenchSimError(f"score_candidates: the pass has no stage {missing[0]} (its stages: {have})")
    stages = have  # the pass's own arrays, no copy

    def flat(name: str, dtype: Any = None) -> np.ndarray:
        return np.ascontiguousarray(ds[name].values.reshape(len(stages), -1), dtype=dtype)

    st = np.asarray(stages, dtype=np.int64)
    off_map = stage_offsets_dn(cfg, stages)
    off = np.array([off_map[int(m)] for m in st])[:, None]
    linear, mean, noise = flat("linear_dn", np.float64), flat("mean_dn", np.float64), flat("noise_std_dn")
    truth = linear - off
    clear = clear_of_clips(linear, mean, noise)
    del linear
    photons = flat("photons", np.float64)
    refl = flat("reflectance")
    regions = [light_regions(photons[i], refl[i]) for i in range(st.size)]
    per_row = photons / st[:, None].astype(np.float64)  # as tdi_light_ratio divides
    light = per_row[-1]
    dark = np.flatnonzero(light <= np.percentile(light, 100.0 * DARK_FRACTION))
    dark_var = np.stack(
        [stage_temporal_var_dn2(cfg, photons[i, dark], int(m), cfg.timing.t_int_s) for i, m in enumerate(st)]
    )
    return _Stacks(
        stages=st,
        off=off,
        dn=flat("dn"),
        truth=truth,
        valid=truth >= 1.0,
        clipped=flat("clipped", bool),
        clear=clear,
        mean=mean,
        noise=noise,
        per_row=per_row,
        spot=np.stack([r["spot"] for r in regions]),
        fill=np.stack([r["fill"] for r in regions]),
        dark=dark,
        dark_var=np.ascontiguousarray(dark_var, dtype=np.float64),
    )


def _word_arrays(s: _Stacks, beta: int, pass_beta: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The signals, ``clipped`` and clearance of every stage at a word of ``beta`` bits from the
    pass's words of ``pass_beta`` bits (module docstring)."""
    if beta == pass_beta:
        return s.dn.astype(np.float64) - s.off, s.clipped, s.clear
    top = word_clip_dn(beta)
    words = np.minimum(s.dn, top)
    clipped = s.clipped | (s.dn >= top)
    clear = s.clear & (top - s.mean >= CLIP_MARGIN_SIGMAS * s.noise)
    return words.astype(np.float64) - s.off, clipped, clear


def _saturations(cfg: BenchConfig, s: _Stacks, rules: Sequence[str]) -> np.ndarray:
    """(rules, stages) saturation levels of the signals [DN] of the clip-aware rules at the word of
    ``cfg``: the word's top less the offset, less a noise margin for ``clip_margin``
    (:func:`bench_sim.measure.fusion_scores.clip_margin_dn`)."""
    top = float(word_clip_dn(cfg.dtdi.beta_bits))
    plain = top - s.off[:, 0]
    out = np.zeros((len(rules), s.stages.size))
    for r, rule in enumerate(rules):
        if rule == "clip":
            out[r] = plain
        elif rule == "clip_margin":
            out[r] = [p - clip_margin_dn(cfg, int(m), p) for m, p in zip(s.stages, plain, strict=True)]
    return out


def _word_sums(
    cfg: BenchConfig, s: _Stacks, space: CandidateSpace, beta: int
) -> dict[tuple[str, int, int, int], np.ndarray]:
    """``(rule, mu1, mu_mid, mu2)`` -> the sums (:data:`FIELDS`) of every candidate of word ``beta``."""
    wcfg = word_config(cfg, beta)
    signal, clipped, clear = _word_arrays(s, beta, space.pass_beta)
    rules = list(space.rules)
    codes = np.array([_CODES[r] for r in rules], dtype=np.int64)
    sat = _saturations(wcfg, s, rules)
    index = {int(m): i for i, m in enumerate(s.stages)}
    tops = sorted({c[-1] for c in (*space.pairs, *space.triples)})
    phi = float(full_scale_dn(beta))

    def one_top(top: int) -> dict[tuple[str, int, int, int], np.ndarray]:
        combos = [(a, 0, b) for a, b in space.pairs if b == top] + [t for t in space.triples if t[2] == top]
        lows = np.array([index[c[0]] for c in combos], dtype=np.int64)
        mids = np.array([index[c[1]] if c[1] else -1 for c in combos], dtype=np.int64)
        out = fusion_sums(
            signal=signal,
            truth=s.truth,
            valid=s.valid,
            clipped=clipped,
            clear=clear,
            photons_per_row=s.per_row,
            spot=s.spot,
            fill=s.fill,
            dark_pixels=s.dark,
            dark_var=s.dark_var,
            stages=s.stages.astype(np.float64),
            top=index[top],
            lows=lows,
            mids=mids,
            codes=codes,
            saturation=sat,
            phi_minus_offset_top=phi - float(s.off[index[top], 0]),
            tolerance=LIGHT_RATIO_TOLERANCE,
        )
        return {
            (rule, c[0], c[1], c[2]): out[j, r] for j, c in enumerate(combos) for r, rule in enumerate(rules)
        }

    sums: dict[tuple[str, int, int, int], np.ndarray] = {}
    for part in parallel_map(one_top, tops):
        sums.update(part)
    return sums


def _scores(sums: np.ndarray, pixels: int) -> dict[str, float]:
    """A candidate's score columns (of :data:`SCORE_COLUMNS` but the closed forms) from its sums."""
    f = dict(zip(FIELDS, sums, strict=True))
    out: dict[str, float] = {}
    nan = float("nan")
    for r in REGIONS:
        n = f[f"{r}_n"]
        suffix = "" if r == "whole" else f"_{r}"
        out[f"truth_bias{suffix}"] = f[f"{r}_sum"] / n if n else nan
        out[f"truth_rms{suffix}"] = float(np.sqrt(f[f"{r}_sumsq"] / n)) if n else nan
        out[f"pixels_{r}"] = n
    out["clipped_share"] = f["from_clipped"] / pixels
    out["low_share"] = f["from_low"] / pixels
    dn_ = f["dark_n"]
    out["snr_dark"] = (
        (f["dark_signal"] / dn_) / float(np.sqrt(f["dark_var"] / dn_)) if dn_ and f["dark_var"] > 0 else nan
    )
    return out


def score_candidates(cfg: BenchConfig, ds: xr.Dataset, space: CandidateSpace) -> PassScores:
    """Score every candidate of ``space`` on one pass (module docstring).

    Parameters
    ----------
    cfg
        The bench of the pass, at the word :attr:`CandidateSpace.pass_beta`.
    ds
        The pass's dataset with its truth at every stage of the space
        (:func:`bench_sim.pipeline.run_pass` with ``truth=True``).
    space
        The candidates.

    Returns
    -------
    PassScores
        One row per candidate (:meth:`CandidateSpace.rows`).
    """
    if rule_unknown := sorted(set(space.rules) - set(RULES)):
        raise BenchSimError(f"score_candidates: rule {rule_unknown[0]!r}: allowed {', '.join(RULES)}")
    if cfg.dtdi.beta_bits != space.pass_beta:
        raise BenchSimError(
            f"score_candidates: the pass has a {cfg.dtdi.beta_bits}-bit word, the space's "
            f"widest is {space.pass_beta} bits"
        )
    s = _stacks(cfg, ds, space.stages)
    pixels = int(s.truth.shape[1])
    rows = space.rows()
    sums: dict[tuple[int, str, int, int, int], np.ndarray] = {}
    for beta in space.words:
        sums.update({(beta, *k): v for k, v in _word_sums(cfg, s, space, beta).items()})
    cols: dict[str, list[Any]] = {
        k: [] for k in ("beta_bits", "rule", "mu1", "mu_mid", "mu2", *SCORE_COLUMNS)
    }
    closed: dict[tuple[int, int, int], tuple[float, float]] = {}
    for row in rows:
        beta, rule, a, mid, b = row
        for k, v in zip(("beta_bits", "rule", "mu1", "mu_mid", "mu2"), row, strict=True):
            cols[k].append(v)
        if (beta, a, b) not in closed:
            wcfg = word_config(cfg, beta)
            dr = hdr_dr_model_db(wcfg, a, b)
            closed[(beta, a, b)] = (dr, hdr_dr_model_db(wcfg, a, b, beta_bits=None) - dr)
        cols["dr_db"].append(closed[(beta, a, b)][0])
        cols["dr_cap_db"].append(closed[(beta, a, b)][1])
        for k, v in _scores(sums[row], pixels).items():
            cols[k].append(v)
    columns = {k: np.asarray(v, dtype=object if k == "rule" else None) for k, v in cols.items()}
    columns["rule"] = columns["rule"].astype(str)
    return PassScores(columns, int(s.dark.size))
