"""The typed result of ``bench-sim reproduce``: what ``metrics.json`` holds and the report reads.

:class:`ReproduceResult` groups the run's facts in sections (:class:`RunShape`,
:class:`DynamicRangeResult`, :class:`Table1Result`, :class:`SceneResult`, :class:`RunRecord`,
:class:`RunTimings`); :meth:`ReproduceResult.to_dict` is ``metrics.json``'s flat dict, the
sections' fields in this order. The three images are keyed ``gamma1``, ``gamma2`` and
``gamma_hdr`` everywhere.
"""

from __future__ import annotations

from dataclasses import MISSING, asdict, dataclass, fields
from typing import Any

from bench_sim.measure.chain_dr import ChainDR
from bench_sim.measure.pass_metrics import PassMetrics

__all__ = [
    "PAPER",
    "RunShape",
    "DynamicRangeResult",
    "Table1Result",
    "SceneResult",
    "RunRecord",
    "TruthResult",
    "SharpnessResult",
    "SeedsResult",
    "RunTimings",
    "ReproduceResult",
]

#: The paper's numbers (Table 1, section 3).
PAPER: dict[str, Any] = {
    "omega": {"gamma1": 28931332, "gamma2": 4689332, "gamma_hdr": 23937472},
    "delta_psi_db": 26.02,
    "mu1": 10,
    "mu2": 80,
}


@dataclass(frozen=True)
class RunShape:
    """What was run: the fused stages ``mu1``, ``mu2``, the output word of ``beta`` bits
    (``phi_fs_dn = 2**beta`` [DN]), the word's pedestal [DN] and the offset each fused stage's
    word carries [DN], the image (``lines`` x ``columns``) from ``frames`` frames of a
    ``rows``-row sensor, the stages of the pass and those of Fig. 3."""

    mu1: int
    mu2: int
    beta: int
    phi_fs_dn: int
    pedestal_dn: int
    stage_offset_dn: dict[str, float]
    lines: int
    columns: int
    rows: int
    frames: int
    stages: list[int]
    fig3_stages: list[int]


@dataclass(frozen=True)
class DynamicRangeResult:
    """Eq. 15 and the dynamic range measured through the chain (:mod:`bench_sim.measure.chain_dr`).

    ``delta_psi_db_eq15``: eq. 15 for ``mu1``, ``mu2`` [dB]; ``paper_delta_psi_db``: the
    paper's 26.02 dB; ``stage_pairs_26_02_db``: the Fig. 3 stage pairs for which eq. 15 gives
    it. ``dr_db`` (EMVA 1288 saturation), ``dr_db_extrapolated``, ``dr_db_model`` (closed form)
    per image [dB]; the gains of ``Gamma_HDR`` over ``Gamma1`` and ``Gamma2`` [dB]; whether the
    gain over ``Gamma2`` is eq. 15 by construction; whether each fused stage clips on the word;
    the eq. 11 switch (:meth:`~bench_sim.measure.chain_dr.ChainDR.fusion_switch`); the whole
    measurement (``dr_details``, :meth:`~bench_sim.measure.chain_dr.ChainDR.as_dict`).
    """

    delta_psi_db_eq15: float
    paper_delta_psi_db: float
    stage_pairs_26_02_db: list[list[int]]
    dr_db: dict[str, float]
    dr_db_extrapolated: dict[str, float]
    dr_db_model: dict[str, float]
    delta_dr_db_vs_gamma1: float
    delta_dr_db_vs_gamma2: float
    delta_dr_db_vs_gamma2_extrapolated: float
    gain_over_gamma2_by_construction: bool
    stage_clips_on_word: dict[str, bool]
    fusion_switch: dict[str, float]
    dr_details: dict[str, Any]

    @classmethod
    def from_chain(
        cls, chain: ChainDR, eq15_db: float, stage_pairs: list[tuple[int, int]]
    ) -> DynamicRangeResult:
        """The section from the chain's measurement, eq. 15 [dB] and its 26.02 dB stage pairs."""
        dr = chain.as_dict()
        return cls(
            delta_psi_db_eq15=eq15_db,
            paper_delta_psi_db=PAPER["delta_psi_db"],
            stage_pairs_26_02_db=[list(p) for p in stage_pairs],
            dr_db=dr["dr_db"],
            dr_db_extrapolated=dr["dr_db_extrapolated"],
            dr_db_model=dr["model_dr_db"],
            delta_dr_db_vs_gamma1=dr["delta_db_vs_gamma1"],
            delta_dr_db_vs_gamma2=dr["delta_db_vs_gamma2"],
            delta_dr_db_vs_gamma2_extrapolated=dr["delta_db_vs_gamma2_extrapolated"],
            gain_over_gamma2_by_construction=dr["gain_over_gamma2_by_construction"],
            stage_clips_on_word={
                "gamma1": dr["stage_clips_on_word"][str(chain.mu1)],
                "gamma2": dr["stage_clips_on_word"][str(chain.mu2)],
            },
            fusion_switch=dr["fusion_switch"],
            dr_details=dr,
        )


@dataclass(frozen=True)
class Table1Result:
    """Table 1 (eq. 16-18): ``omega`` per image, the paper's, the histogram variance before the
    division by M*N (``sigma^2[rho(tau_k)]`` of eq. 17), the binning and whether eq. 18 holds."""

    omega: dict[str, float]
    omega_paper: dict[str, int]
    histogram_variance: dict[str, float]
    omega_binning: dict[str, Any]
    eq18_holds: bool

    @classmethod
    def from_pass(cls, pm: PassMetrics, pixels: int) -> Table1Result:
        """The section from a pass's metrics and its image's ``pixels`` (M*N)."""
        eq18 = pm.eq18
        omega = {"gamma1": eq18.omega1, "gamma2": eq18.omega2, "gamma_hdr": eq18.omega_hdr}
        return cls(
            omega=omega,
            omega_paper=PAPER["omega"],
            histogram_variance={k: v * pixels for k, v in omega.items()},
            omega_binning={
                k: v for k, v in eq18.as_dict().items() if k in ("stage_binning", "hdr_binning", "variance")
            },
            eq18_holds=eq18.holds,
        )


@dataclass(frozen=True)
class SceneResult:
    """The scene-referred metrics of the pass (:class:`~bench_sim.measure.pass_metrics.PassMetrics`):
    saturated fractions (at the word's top), the darkest and brightest wedge patches, the paper's
    qualitative claims and, where the run had the truth, the fraction of each image's pixels
    clipped anywhere (pixel, ADC or word: the truth's clip flags; ``None`` where not given)."""

    saturated_fraction: dict[str, float]
    darkest_patch: dict[str, Any]
    brightest_patch: dict[str, Any]
    qualitative: dict[str, bool]
    clipped_fraction: dict[str, float] | None = None


@dataclass(frozen=True)
class RunRecord:
    """Provenance: seed, config hash, version, render engine and its variant."""

    seed: int
    config_sha256: str
    version: str
    engine: str
    variant: str


@dataclass(frozen=True)
class RunTimings:
    """Facts of this process, not of the result: seconds per step, the wall time [s], and the
    Mitsuba renders made (fewer when the records were cached)."""

    timings_s: dict[str, float]
    wall_s: float
    mitsuba_renders: int


@dataclass(frozen=True)
class TruthResult:
    """Gamma_HDR against its exact truth (:class:`bench_sim.measure.fusion_scores.FusionScores`'s
    summary): the light ratio of the TDI window and, per rule (eq. 11, the clip-aware rule), the
    relative errors per region and the pixels taken from a clipped stage."""

    fusion_truth: dict[str, Any]


@dataclass(frozen=True)
class SharpnessResult:
    """The sharpness of the bench (:func:`bench_sim.workflows.reproduce.stage_mtf.sharpness_result`):
    its lens, the companion pass's e-SFR -- the median over its stages of the MTF50 [cycles/px]
    and of the SFR at Nyquist, across and along the track -- beside the closed form across the
    track at the companion's edge angle (lens x pixel aperture, and with the e-SFR's 1/4-px bins),
    its MTF50, and the warning when the system's MTF50 lies above Nyquist (else ``None``)."""

    lens: str
    sharpness_stages: list[int]
    mtf50_across_cyc_px: float | None
    mtf50_along_cyc_px: float | None
    mtf_nyquist_across: float | None
    mtf_nyquist_along: float | None
    closed_nyquist_across: float
    closed_nyquist_across_binned: float
    closed_mtf50_across_cyc_px: float | None
    nyquist_warning: str | None


@dataclass(frozen=True)
class SeedsResult:
    """``reproduce --seeds N``: the seeds and, per headline number, its mean, sample standard
    deviation and values over them (:mod:`bench_sim.workflows.reproduce.seeds`)."""

    seeds: list[int]
    spread: dict[str, Any]


@dataclass(frozen=True)
class ReproduceResult:
    """Everything ``reproduce`` measured; ``timings`` is ``None`` until the run is timed."""

    shape: RunShape
    dynamic_range: DynamicRangeResult
    table1: Table1Result
    scene: SceneResult
    record: RunRecord
    timings: RunTimings | None = None
    truth: TruthResult | None = None
    seeds: SeedsResult | None = None
    sharpness: SharpnessResult | None = None

    def to_dict(self) -> dict[str, Any]:
        """``metrics.json``'s dict: the sections' fields, flat, in order."""
        parts: list[Any] = [self.shape, self.dynamic_range, self.table1, self.scene, self.record]
        if self.truth is not None:
            parts.append(self.truth)
        if self.sharpness is not None:
            parts.append(self.sharpness)
        if self.seeds is not None:
            parts.append(self.seeds)
        if self.timings is not None:
            parts.append(self.timings)
        out: dict[str, Any] = {}
        for part in parts:
            out.update(asdict(part))
        return out

    @classmethod
    def from_dict(cls, metrics: dict[str, Any]) -> ReproduceResult:
        """The result back from :meth:`to_dict`'s dict (``metrics.json``); the optional sections
        (timings, truth, seeds) are ``None`` where their fields are absent."""

        def section(kind: Any) -> Any:
            names = [f.name for f in fields(kind)]
            required = [f.name for f in fields(kind) if f.default is MISSING]
            if not all(n in metrics for n in required):
                return None
            return kind(**{n: metrics[n] for n in names if n in metrics})

        return cls(
            shape=section(RunShape), dynamic_range=section(DynamicRangeResult),
            table1=section(Table1Result), scene=section(SceneResult), record=section(RunRecord),
            timings=section(RunTimings), truth=section(TruthResult), seeds=section(SeedsResult),
            sharpness=section(SharpnessResult),
        )
