"""Sharpness per stage in the reproduction: MTF50 along and across the track versus the stage.

The paper target has no slanted edge (its wedge steps and bars are aligned with the pixel grid,
where the ISO 12233 e-SFR cannot oversample the edge, and the Siemens star's spokes lie 5 deg
apart, too close for one edge per ROI). So the reproduction measures sharpness on a companion
pass of the *same bench* -- drum, lens, lights, sensor, timing, DTDI, fusion -- with the target
swapped for ``target.layout = "slanted_edges"`` (128-pixel cells, edges at 5 +- 1 deg), over
:data:`COMPANION_LINES` lines and at most :data:`COMPANION_COLUMNS` columns, at the stages
:data:`MTF_STAGES` (those the sensor has) and ``mu1``, ``mu2``. Through a lens that blurs
(:func:`bench_sim.rig.lens_psf.lens_otf`: diffraction by default) the target is drawn at
:data:`COMPANION_TEXELS_PER_PIXEL` texels per pixel: at the default 4 the drawn edge itself (its
map, the map's interpolation and the texture's) costs 7 % of the SFR at Nyquist, at 8 about
2 %, so the lens is measured and not the drawing; a perfect lens keeps the bench's texels (the
numbers of bench_sim 0.3). Its generator is a child of
the run's seed apart from the main pass's stream, so the main results do not change.
The e-SFR per stage and of ``Gamma_HDR`` is :func:`bench_sim.measure.sharpness.add_sharpness`.

**Noise-free** (:func:`noise_free`): measured on the expected words (``mean_dn``, every clip in)
of a pass whose sensor has no fixed pattern (PRNU, DSNU and column offsets off), and on eq. 11 of
those words, so that no noise makes a trend: temporal noise raises stage 1's MTF50 by several per
cent on a noisy pass (its ESF is noisier than the summed stages'), and the spatial noise falls with
the stage like the temporal one. What changes with the stage is then the optics' and the motion's:
with a sync error, the along-track spread of the summed rows (and, through the edges' slant, a
little of the across-track MTF50).

Outputs: ``mtf50_vs_stage.png`` and ``mtf50_vs_stage.csv`` (stage, MTF50 along and across the
track in cycles/px, and the same for ``Gamma_HDR`` in the last row, ``stage`` = ``gamma_hdr``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig, with_overrides
from bench_sim.fusion.stage_pair import fuse_stage_words
from bench_sim.io import write_csv, write_figure_png
from bench_sim.measure.sharpness import SFR_FREQUENCY_CYC_PX, PassSharpness, pass_sharpness
from bench_sim.metrics.sfr_readings import mtf50
from bench_sim.pipeline import run_pass
from bench_sim.render.exposures import release
from bench_sim.rig.lens_psf import lens_mtf_across, lens_otf
from bench_sim.workflows.preflight import nyquist_warning
from bench_sim.workflows.reproduce.result import SharpnessResult

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["MTF_STAGES", "COMPANION_LINES", "COMPANION_COLUMNS", "COMPANION_TEXELS_PER_PIXEL",
           "COMPANION_EDGE_ANGLE_DEG", "companion_config", "measure_stage_mtf", "sharpness_result",
           "write_stage_mtf", "noise_free", "NOISE_FREE", "mtf50_vs_stage_section", "StageMTF"]

#: stages measured (those up to ``sensor.rows``), besides ``mu1`` and ``mu2``
MTF_STAGES: tuple[int, ...] = (1, 10, 20, 40, 60, 80, 100)
#: lines and largest number of columns of the companion pass
COMPANION_LINES = 192
COMPANION_COLUMNS = 256
#: how the companion pass is made noise-free (the figure and the CSV say it)
NOISE_FREE = "noise-free: expected words (mean_dn) of a pass without fixed-pattern noise, and eq. 11 of them"
#: texels per pixel of the companion's target through a lens that blurs (module docstring)
COMPANION_TEXELS_PER_PIXEL = 8
#: the companion's edges' mean angle to the pixel axes [deg]
COMPANION_EDGE_ANGLE_DEG = 5.0
#: the companion pass's variables its e-SFRs read (:func:`bench_sim.measure.sharpness.pass_sharpness`
#: on :func:`noise_free` images: the words' expectations, the light, the clips, the fusion's source)
COMPANION_VARIABLES = ("dn", "mean_dn", "photons", "reflectance", "clipped", "gamma_hdr", "gamma_hdr_source")


def companion_config(cfg: BenchConfig) -> BenchConfig:
    """The bench ``cfg`` with a slanted-edge target, :data:`COMPANION_LINES` lines, at most
    :data:`COMPANION_COLUMNS` columns and no fixed-pattern noise (PRNU, DSNU, column offsets; module
    docstring)."""
    target: dict[str, Any] = {"layout": "slanted_edges", "edge_cell_px": 128,
                              "edge_angle_deg": COMPANION_EDGE_ANGLE_DEG, "edge_angle_jitter_deg": 1.0}
    if lens_otf(cfg) is not None:
        target["texels_per_pixel"] = max(cfg.target.texels_per_pixel, COMPANION_TEXELS_PER_PIXEL)
    return with_overrides(cfg, {
        "lines": COMPANION_LINES,
        "sensor": {"columns": min(cfg.sensor.columns, COMPANION_COLUMNS), "prnu_enabled": False,
                   "dsnu_enabled": False, "column_fpn": False},
        "target": target,
    })


def _fused_expected(cfg: BenchConfig, mean1: np.ndarray, mean2: np.ndarray) -> dict[str, np.ndarray]:
    """``gamma_hdr`` and ``gamma_hdr_source`` of eq. 11 of the expected words ``mean1``, ``mean2`` of
    stages ``mu1``, ``mu2`` (their dtypes in a pass)."""
    fused = fuse_stage_words(cfg, mean1, mean2)
    return {"gamma_hdr": fused.hdr.astype(np.float32), "gamma_hdr_source": fused.source.astype(np.int16)}


def noise_free(ds: xr.Dataset, cfg: BenchConfig) -> xr.Dataset:
    """A pass's dataset (with its truth) with the words ``dn`` replaced by their expectations
    ``mean_dn`` and ``gamma_hdr`` (and its source) by eq. 11 of them
    (:func:`bench_sim.fusion.stage_pair.fuse_stage_words`): the images without temporal noise."""
    out = ds.assign(dn=ds["mean_dn"])
    mu1, mu2 = cfg.fusion.mu1, cfg.fusion.mu2
    if "gamma_hdr" in ds:
        mean = ds["mean_dn"]
        fused = _fused_expected(cfg, mean.sel(stage=mu1).values, mean.sel(stage=mu2).values)
        for name, values in fused.items():
            out[name] = (ds[name].dims, values, ds[name].attrs)
    return out


@dataclass(frozen=True)
class StageMTF:
    """The companion pass's sharpness (:func:`measure_stage_mtf`): its ``stages`` and the e-SFRs of
    their noise-free images (``None``: no edge found)."""

    stages: list[int]
    sharpness: PassSharpness | None

    def mtf50(self, direction: str) -> np.ndarray:
        """MTF50 per stage [cycles/px] (NaN without edges)."""
        if self.sharpness is None:
            return np.full(len(self.stages), np.nan)
        return np.array([s[direction].mtf50_cyc_px for s in self.sharpness.per_stage])

    def sfr(self, direction: str) -> np.ndarray:
        """The mean e-SFR per stage on :data:`bench_sim.measure.sharpness.SFR_FREQUENCY_CYC_PX`."""
        if self.sharpness is None:
            return np.full((len(self.stages), SFR_FREQUENCY_CYC_PX.size), np.nan)
        return np.stack([s[direction].sfr for s in self.sharpness.per_stage])

    def hdr_mtf50(self, direction: str) -> float | None:
        """``Gamma_HDR``'s MTF50 [cycles/px] (``None`` without it or NaN)."""
        hdr = None if self.sharpness is None else self.sharpness.hdr
        return None if hdr is None else _num(hdr[direction].mtf50_cyc_px)


def measure_stage_mtf(
    cfg: BenchConfig, seed: int, stages: Sequence[int] | None = None, *, release_render: bool = False
) -> StageMTF:
    """The companion pass (module docstring), noise-free (:func:`noise_free`, on the pass's arrays:
    no dataset is built), with its e-SFR per stage and of ``Gamma_HDR``; at ``stages`` and ``mu1``,
    ``mu2`` if given (``bench-sim design``: every candidate stage), else at :data:`MTF_STAGES`.
    ``release_render``: the pass's render state let go as soon as it is done
    (:func:`bench_sim.render.exposures.release`; a run that makes no other companion pass)."""
    comp = companion_config(cfg)
    chosen = MTF_STAGES if stages is None else tuple(stages)
    stages = sorted({m for m in chosen if m <= cfg.sensor.rows} | {cfg.fusion.mu1, cfg.fusion.mu2})
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(2)[1])
    sim = run_pass(comp, stages, rng, truth=True, variables=COMPANION_VARIABLES)
    if release_render:
        release(sim.setup)
    assert sim.arrays is not None
    has = set(sim.arrays.arrays)
    mu1, mu2 = comp.fusion.mu1, comp.fusion.mu2
    images = _fused_expected(comp, sim.stage_array("mean_dn", mu1), sim.stage_array("mean_dn", mu2)) \
        if "gamma_hdr" in has else {}

    def read(name: str, m: int | None) -> np.ndarray:
        return images[name] if m is None else sim.stage_array("mean_dn" if name == "dn" else name, m)

    return StageMTF(list(stages), pass_sharpness(read, stages, has, comp))


def _num(v: Any) -> float | None:
    f = float(v)
    return None if math.isnan(f) else f


def _median(values: Any) -> float | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else None


def sharpness_result(res: StageMTF, cfg: BenchConfig) -> SharpnessResult:
    """The bench's sharpness for the report (:class:`SharpnessResult`) from the companion pass
    ``res``: medians over its stages, and the closed form across the track at the companion's edge
    angle ``t``: ``lens(f) sinc(f cos t) sinc(f sin t)`` at Nyquist, and that times the e-SFR's
    bins ``sinc(f cos(t) / 4)``."""
    t = math.radians(COMPANION_EDGE_ANGLE_DEG)
    f = np.linspace(0.0, 1.0, 2001)
    closed = lens_mtf_across(cfg, f) * np.abs(np.sinc(f * math.cos(t)) * np.sinc(f * math.sin(t)))
    nyq = float(np.interp(0.5, f, closed))
    have = res.sharpness is not None
    k = int(np.argmin(np.abs(SFR_FREQUENCY_CYC_PX - 0.5)))
    otf = lens_otf(cfg)
    return SharpnessResult(
        lens="a perfect lens (lens.diffraction = false)" if otf is None else otf.source,
        sharpness_stages=list(res.stages),
        mtf50_across_cyc_px=_median(res.mtf50("across")) if have else None,
        mtf50_along_cyc_px=_median(res.mtf50("along")) if have else None,
        mtf_nyquist_across=_median(res.sfr("across")[:, k]) if have else None,
        mtf_nyquist_along=_median(res.sfr("along")[:, k]) if have else None,
        closed_nyquist_across=nyq,
        closed_nyquist_across_binned=nyq * float(np.sinc(0.5 * math.cos(t) / 4)),
        closed_mtf50_across_cyc_px=_num(mtf50(f, closed)),
        nyquist_warning=nyquist_warning(cfg),
    )


def write_stage_mtf(res: StageMTF, cfg: BenchConfig, folder: Path, meta: dict[str, Any]) -> list[str]:
    """``mtf50_vs_stage.csv`` and ``.png`` of the companion pass ``res`` of the bench ``cfg`` in
    ``folder`` (module docstring); returns the names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = dict(meta, figure="MTF50 versus stage (ISO 12233 e-SFR, companion pass with a "
                f"slanted_edges target on the same bench; {NOISE_FREE})", noise=NOISE_FREE)
    stages = list(res.stages)
    along, across = res.mtf50("along"), res.mtf50("across")
    rows: list[list[Any]] = [[m, _num(a), _num(c)] for m, a, c in zip(stages, along, across, strict=True)]
    hdr = {d: res.hdr_mtf50(d) for d in ("along", "across")}
    rows.append(["gamma_hdr", hdr["along"], hdr["across"]])
    header = ["stage", "mtf50_along_cyc_px", "mtf50_across_cyc_px"]
    write_csv(folder / "mtf50_vs_stage.csv", header, rows, meta)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    ax.plot(stages, along, "o-", color="C0", label="along the track (lines)")
    ax.plot(stages, across, "s-", color="C1", label="across the track (columns)")
    for (d, v), color in zip(hdr.items(), ("C0", "C1"), strict=True):
        if v is not None:
            ax.axhline(v, color=color, ls=":", lw=1, label=f"Gamma_HDR, {d}")
    ax.set_xlabel("DTDI stage m")
    ax.set_ylabel("MTF50 [cycles/px]")
    ax.set_ylim(0, 0.8)
    ax.set_title(f"MTF50 per stage, ISO 12233 e-SFR (slanted edges; sync error {cfg.timing.sync_error:g};\n"
                 "noise-free: expected words, no fixed pattern)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_figure_png(folder / "mtf50_vs_stage.png", fig, meta, dpi=100)
    return ["mtf50_vs_stage.csv", "mtf50_vs_stage.png"]


def mtf50_vs_stage_section(cfg: BenchConfig) -> list[str]:
    """The report's lines on ``mtf50_vs_stage``: how it is measured (noise-free) and what depends on
    the stage under the bench's sync error (along the track, and through the edges' slant a little
    across it)."""
    eps = cfg.timing.sync_error
    motion = (
        f"With this bench's sync error ({eps:g} line per line period) the m rows of stage m see a scene line "
        f"spread over m x {abs(eps):g} pixels along the track: the along-track MTF50 falls with the stage, "
        "and so, a little, does the across-track MTF50: the slanted edges project that spread across the "
        "track by the tangent of their angle (5 +- 1 deg)."
        if eps else
        "Without a sync error nothing along the track changes with the stage but the noise, so the "
        "noise-free MTF50s are the same at every stage; with a sync error e the m rows of stage m see "
        "a scene line spread over m e pixels along the track, the along-track MTF50 falls with the "
        "stage and, through the slanted edges' angle, the across-track MTF50 a little too."
    )
    return [
        "`mtf50_vs_stage.png` and `.csv`: the ISO 12233 e-SFR's MTF50 along and across the track per "
        "stage, on a companion pass of this bench with slanted edges (the paper target has none), "
        f"{NOISE_FREE}, so that no noise makes a trend (on noisy words stage 1's MTF50 reads several "
        f"per cent high). {motion}", "",
    ]
