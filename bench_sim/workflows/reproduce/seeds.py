"""``reproduce --seeds N``: the headline numbers over ``N`` seeds as mean +- standard deviation.

:func:`check_seeds` refuses, before any work, a count above :data:`MAX_SEEDS` (with the time it
would take, :func:`seconds_per_seed`) and a last seed ``seed + N - 1`` outside the seed rule
(:func:`bench_sim.workflows.preflight.is_seed`); a run estimated above :data:`LONG_RUN_S` is
warned about with its estimate.

Seed ``s`` of ``seed .. seed + N - 1`` draws a new sensor (fixed patterns) and new temporal noise
(and, with the reference engine, new render noise); the bench, the target and the lights are the
same. :func:`headline_numbers` picks the run's headline numbers out of ``metrics.json``'s dict,
:func:`seed_spread` gives their mean and sample standard deviation, :func:`spread_section` the
report's section. Spatial SNRs (mean over the standard deviation of a patch: shading and fixed
pattern count as noise) are labelled as such.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.io import markdown_table
from bench_sim.workflows.preflight import SEED_MAX, SEED_RULE, is_seed

__all__ = [
    "headline_numbers", "seed_spread", "spread_section", "check_seeds", "seconds_per_seed", "HEADLINES",
    "MAX_SEEDS", "PIXEL_READS_PER_S", "LONG_RUN_S",
]

#: Most seeds one ``reproduce --seeds`` runs (more: several runs with their own ``--seed``)
MAX_SEEDS = 1000
#: Pixel reads per second of a further seed's pass, fusion, chain DR and metrics, for the time
#: estimate: about what 2 cores do (measured: the paper rig's 115 M reads in about 13 s a seed,
#: the quick preset's 18 M in about 1.1 s)
PIXEL_READS_PER_S = 1e7
#: Estimated run time [s] above which ``--seeds`` is warned about
LONG_RUN_S = 600.0

#: headline number -> (path in metrics.json's dict, label in the report)
HEADLINES: dict[str, tuple[tuple[str, ...], str]] = {
    "dr_db_gamma1": (("dr_db", "gamma1"), "DR of Gamma1 [dB] (through the chain, temporal)"),
    "dr_db_gamma2": (("dr_db", "gamma2"), "DR of Gamma2 [dB] (through the chain, temporal)"),
    "dr_db_gamma_hdr": (("dr_db", "gamma_hdr"), "DR of Gamma_HDR [dB] (through the chain, temporal)"),
    "gain_db_vs_gamma1": (("delta_dr_db_vs_gamma1",), "gain over Gamma1 [dB]"),
    "gain_db_vs_gamma2": (("delta_dr_db_vs_gamma2",), "gain over Gamma2 [dB]"),
    "snr_darkest_gamma1": (("darkest_patch", "snr", "gamma1"), "spatial SNR, darkest patch, Gamma1"),
    "snr_darkest_gamma2": (("darkest_patch", "snr", "gamma2"), "spatial SNR, darkest patch, Gamma2"),
    "snr_darkest_gamma_hdr": (("darkest_patch", "snr", "gamma_hdr"), "spatial SNR, darkest patch, Gamma_HDR"),
    "truth_bias_eq11": (("fusion_truth", "rules", "eq11", "error", "whole", "bias"),
                        "eq. 11: mean relative error against truth, whole image"),
    "truth_rms_eq11": (("fusion_truth", "rules", "eq11", "error", "whole", "rms"),
                       "eq. 11: RMS relative error against truth, whole image"),
    "truth_bias_eq11_edge": (("fusion_truth", "rules", "eq11", "error", "spot_edge", "bias"),
                             "eq. 11: mean relative error where r leaves 1 +- tol"),
    "from_clipped_eq11": (("fusion_truth", "rules", "eq11", "from_clipped_fraction"),
                          "eq. 11: fraction of pixels from a clipped stage"),
    "truth_rms_clip": (("fusion_truth", "rules", "clip", "error", "whole", "rms"),
                       "clip-aware: RMS relative error against truth, whole image"),
}


def _get(d: Any, path: tuple[str, ...]) -> float | None:
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return None
        d = d[key]
    return float(d) if isinstance(d, int | float) and not isinstance(d, bool) else None


def headline_numbers(metrics: dict[str, Any]) -> dict[str, float | None]:
    """The :data:`HEADLINES` of one run's ``metrics.json`` dict (``None`` where absent)."""
    return {name: _get(metrics, path) for name, (path, _) in HEADLINES.items()}


def seed_spread(runs: Sequence[dict[str, float | None]]) -> dict[str, dict[str, Any]]:
    """Per headline: ``mean``, ``sd`` (sample standard deviation, ``n - 1``; 0 for one run),
    ``n`` and the ``values`` (finite ones only)."""
    out: dict[str, dict[str, Any]] = {}
    for name in HEADLINES:
        vals = [v for r in runs if (v := r.get(name)) is not None and math.isfinite(v)]
        n = len(vals)
        mean = sum(vals) / n if n else float("nan")
        var = sum((v - mean) ** 2 for v in vals) / (n - 1) if n > 1 else 0.0
        out[name] = {"mean": mean, "sd": math.sqrt(var), "n": n, "values": vals}
    return out


def spread_section(spread: dict[str, dict[str, Any]], seeds: Sequence[int]) -> list[str]:
    """``## Spread over N seeds``: every headline number as mean +- sd."""
    rows = [
        [HEADLINES[k][1], f"{v['mean']:.4g} +- {v['sd']:.2g}", str(v["n"])]
        for k, v in spread.items() if v["n"]
    ]
    return [
        f"## Spread over {len(seeds)} seeds ({seeds[0]}..{seeds[-1]})",
        "",
        "Each seed draws a new sensor (fixed patterns) and new temporal noise on the same bench; "
        "mean +- sample standard deviation. Spatial SNRs are mean / standard deviation over a patch "
        "(shading and fixed pattern count as noise); the DRs are measured through the chain from "
        "temporal statistics.",
        "",
        *markdown_table(["headline number", "mean +- sd", "seeds"], rows),
        "",
    ]


def seconds_per_seed(cfg: BenchConfig, stages: Sequence[int]) -> float:
    """Estimated time [s] of one further seed: its pass's pixel reads (``lines + max(stages) - 1``
    line periods of ``max(stages)`` rows of ``columns`` pixels) at :data:`PIXEL_READS_PER_S`."""
    top = max(int(m) for m in stages)
    return (cfg.lines + top - 1) * top * cfg.sensor.columns / PIXEL_READS_PER_S


def _duration(seconds: float) -> str:
    """``42 s``, ``12 min``, ``3.5 h``, ``9 days``, ``2.1e+05 years``."""
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.0f} s"


def check_seeds(seed: int, seeds: object, cfg: BenchConfig, stages: Sequence[int]) -> int:
    """``--seeds`` checked before any work: an integer in ``1..MAX_SEEDS`` whose last seed
    ``seed + seeds - 1`` is a root seed; a run estimated above :data:`LONG_RUN_S` is warned
    about. Raises :class:`~bench_sim.errors.BenchSimError` (one line) otherwise."""
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise BenchSimError(f"--seeds = {seeds!r}: must be an integer >= 1")
    each = seconds_per_seed(cfg, stages)
    if seeds > MAX_SEEDS:
        raise BenchSimError(
            f"--seeds = {seeds}: more than {MAX_SEEDS} seeds (each reruns the pass, the fusion and the "
            f"chain DR, about {_duration(each)} each for this config: {_duration(each * (seeds - 1))} in "
            "all); run fewer, or several runs each with its own --seed"
        )
    last = seed + seeds - 1
    if not is_seed(last):  # the seed rule, on the last seed run
        raise BenchSimError(
            f"--seed = {seed}, --seeds = {seeds}: the last seed, {last}, must be {SEED_RULE} (seeds are "
            f"stored as signed 64-bit integers); give --seed <= {SEED_MAX - seeds + 1}"
        )
    if each * (seeds - 1) > LONG_RUN_S:
        warnings.warn(
            f"bench_sim: --seeds = {seeds}: about {_duration(each * (seeds - 1))} for the {seeds - 1} "
            f"further seeds (about {_duration(each)} each)",
            UserWarning, stacklevel=2,
        )
    return seeds
