"""``bench-sim ptc``: the photon-transfer series (EMVA 1288 R4) of DTDI stages, as files.

``bench-sim ptc [CONFIG] --stages 1,10,80 --seed S --out DIR`` runs :func:`run_ptc`: the
preflight, then the measurement of :mod:`bench_sim.measure.ptc` (:func:`~bench_sim.measure.ptc.plan_ptc`
-> :func:`~bench_sim.measure.ptc.measure_ptc` -> :func:`~bench_sim.measure.ptc.analyse_ptc`),
then :func:`write_ptc` (the files, as one output set).

Files (DIR, written as one set)
-------------------------------
* ``stage_MMM/emva1288.txt``: EMVA 1288 descriptor (``n bits width height``; per level
  ``b exposure_ns photons`` and its two ``i images/...tif`` lines; ``d exposure_ns`` and the
  dark pair; then the spatial stacks), read by the ``emva1288`` reference package; images are
  16-bit TIFF, so ``dtdi.beta_bits > 16`` is refused with a clear error.
* ``ptc_results.json``: per stage K, QE, dark temporal noise, saturation capacity, SNR curve,
  dynamic range, DSNU and PRNU (measured and model), the series.
* ``stage_MMM/ptc_table.csv``: the stage's photon-transfer table in the format ``bench-sim
  calibrate`` reads (:mod:`bench_sim.workflows.calibrate_inputs`).
* ``ptc_levels.csv`` (every level of every stage), ``ptc_summary.csv`` (one row per stage).
* ``ptc.png`` (photon transfer: variance vs mean), ``snr.png`` (SNR vs photons per frame).

Every file carries the provenance (:func:`bench_sim.runtime.provenance.provenance`).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021); the descriptor file format of the EMVA 1288
reference software.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.io import (
    output_set,
    write_csv,
    write_emva_descriptor,
    write_figure_png,
    write_json,
    write_tiff16,
)
from bench_sim.measure.ptc import (
    DEFAULT_DENSE_LEVELS,
    DEFAULT_LINES,
    DEFAULT_LOG_LEVELS,
    DEFAULT_SPATIAL_IMAGES,
    PtcImages,
    PtcPlan,
    StageResult,
    analyse_ptc,
    measure_ptc,
    plan_ptc,
    stage_quantization_var_dn2,
)
from bench_sim.workflows.area_ptc_job import run_area_ptc
from bench_sim.workflows.estimates import estimate_ptc
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed, preflight
from bench_sim.workflows.simulate import parse_stages_arg

__all__ = ["write_ptc", "run_ptc", "run_ptc_command", "SUMMARY_COLUMNS"]

def _plots(results: dict[int, StageResult]) -> dict[str, Any]:
    """The PTC and SNR figures (matplotlib, not yet written)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: dict[str, Any] = {}
    fig, ax = plt.subplots(figsize=(7, 5))
    for m, r in results.items():
        sig = r.mean_dn - r.dark_mean_dn
        var = r.var_dn2 - r.dark_var_dn2
        ok = (sig > 0) & (var > 0)
        (line,) = ax.loglog(sig[ok], var[ok], "o", ms=3, label=f"stage {m}")
        xs = np.geomspace(max(sig[ok].min(), 1e-3), r.measured.saturation_signal_dn, 50)
        ax.loglog(xs, r.measured.k_dn_per_e * xs, "-", color=line.get_color(), lw=0.8)
    ax.set_xlabel(r"$\mu_y - \mu_{y.dark}$ [DN]")
    ax.set_ylabel(r"$\sigma_y^2 - \sigma_{y.dark}^2$ [DN$^2$]")
    ax.set_title("Photon transfer (lines: fitted K)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    figs["ptc.png"] = fig

    fig, ax = plt.subplots(figsize=(7, 5))
    for m, r in results.items():
        ok = np.isfinite(r.snr) & (r.snr > 0)
        ok[r.measured.saturation.index + 1 :] = False
        (line,) = ax.loglog(r.photons_per_frame[ok], r.snr[ok], "o", ms=3, label=f"stage {m}")
        ax.loglog(r.photons_per_frame[ok], r.snr_model[ok], "-", color=line.get_color(), lw=0.8)
    ax.axhline(1.0, color="k", lw=0.5)
    ax.set_xlabel(r"$\mu_p$ per frame [photons/pixel]")
    ax.set_ylabel("SNR")
    ax.set_title("SNR vs irradiation (lines: linear model)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    figs["snr.png"] = fig
    return figs


SUMMARY_COLUMNS = (
    "K_dn_per_e", "quantum_efficiency", "dark_temporal_noise_dn", "dark_temporal_noise_e",
    "saturation_signal_dn", "saturation_capacity_e", "photons_sat", "photons_min",
    "photons_min_model", "dynamic_range_db", "dynamic_range_db_model", "snr_max",
)


def _write_stage(
    sdir: Path, cfg: BenchConfig, m: int, plan: PtcPlan, images: PtcImages, img_meta: dict[str, Any]
) -> None:
    """Stage ``m``'s 16-bit TIFF images and its EMVA 1288 descriptor into ``sdir``."""

    def save(name: str, img: np.ndarray, photons: float, tag: str) -> str:
        meta = {**img_meta, "stage": m, "photons": photons, "image": tag, "offset_dn": plan.offsets_dn[m]}
        write_tiff16(sdir / name, img.astype(np.uint16), meta)
        return name

    bright: list[tuple[float, float, list[str]]] = []
    dark: list[tuple[float, list[str]]] = []
    exposure_ns = m * cfg.timing.t_int_s * 1e9
    for idx, stack in enumerate(images.pairs[m]):
        ph = float(m * plan.all_levels[idx])
        kind = "dark" if idx == 0 else f"bright_{idx:03d}"
        names = [save(f"images/{kind}_{tag}.tif", img, ph, tag) for tag, img in zip("ab", stack, strict=True)]
        if idx == 0:
            dark.append((exposure_ns, names))
        else:
            bright.append((exposure_ns, ph, names))
    ph50 = float(m * plan.spatial_photons[m])
    sp_bright = [
        save(f"images/spatial_bright_{i:03d}.tif", img, ph50, f"spatial {i}")
        for i, img in enumerate(images.spatial_bright[m])
    ]
    sp_dark = [
        save(f"images/spatial_dark_{i:03d}.tif", img, 0.0, f"spatial {i}")
        for i, img in enumerate(images.spatial_dark[m])
    ]
    write_emva_descriptor(
        sdir / "emva1288.txt", bits=cfg.dtdi.beta_bits, width=plan.columns, height=plan.lines,
        bright=[*bright, (exposure_ns, ph50, sp_bright)], dark=[*dark, (exposure_ns, sp_dark)],
        metadata=img_meta,
        title=f"EMVA 1288 descriptor: bench_sim photon-transfer series of DTDI stage {m}; "
        "photons: mean photons per pixel summed over the stage's frames; exposure: ns",
    )


#: What every file of the series says about the measurement (``ptc_results.json``'s ``notes``).
NOTES = (
    "Two images per level: lines 0..L-1 and L..2L-1 of one DTDI pass of "
    "2L + max(stages) - 1 frames over the top-left max(stages) rows.",
    "photons = mean photons per pixel summed over the m frames of stage m; exposure = "
    "m * t_int.",
    "The word pedestal keeps the dark signal unclipped (EMVA 1288): the configured "
    "dtdi.pedestal_dn, raised where needed to 5 sigma of the highest stage's dark spread.",
    "Saturation: maximum of the temporal variance, refined between levels (parabola); "
    "dynamic_range_db_by_saturation_method gives the grid maximum (EMVA) and the "
    "linear extrapolation to the clipped plateau as well.",
)


def _results_json(
    meta: dict[str, Any], cfg: BenchConfig, plan: PtcPlan, results: dict[int, StageResult]
) -> dict[str, Any]:
    """``ptc_results.json``'s dict, less its ``files``."""
    st, lines = plan.stages, plan.lines
    return {
        **meta,
        "experiment": "ptc",
        "stages": list(st),
        "image_lines": lines,
        "image_columns": plan.columns,
        "frames_per_level": 2 * lines + st[-1] - 1,
        "t_int_s": cfg.timing.t_int_s,
        "beta_bits": cfg.dtdi.beta_bits,
        "subtract_black": cfg.dtdi.subtract_black,
        "pedestal_dn": plan.pedestal_dn,
        "configured_pedestal_dn": cfg.dtdi.pedestal_dn,
        "levels": int(plan.all_levels.size),
        "spatial_images": plan.spatial_images,
        "notes": list(NOTES),
        "results": {str(m): r.as_dict() for m, r in results.items()},
    }


def _level_rows(plan: PtcPlan, results: dict[int, StageResult]) -> list[list[Any]]:
    """``ptc_levels.csv``'s rows: the dark level and every lit level of every stage."""
    rows: list[list[Any]] = []
    for m, r in results.items():
        d = r.as_dict()["series"]
        rows.append([m, 0, 0.0, 0.0, r.dark_mean_dn, r.dark_var_dn2, 0.0, ""])
        for i in range(plan.levels.size):
            snr_v = d["snr"][i]
            rows.append([
                m, i + 1, d["photons_per_frame"][i], d["photons"][i], d["mean_dn"][i],
                d["var_dn2"][i], d["signal_dn"][i], "" if snr_v is None else float(snr_v),
            ])
    return rows


#: Columns of ``stage_MMM/ptc_table.csv``: the photon-transfer table ``bench-sim calibrate`` reads.
TABLE_COLUMNS = (
    "exposure_s", "photons_per_pixel", "mean_dn", "var_dn2", "pixels", "bits", "quantization_var_dn2",
)


def _table_rows(cfg: BenchConfig, m: int, plan: PtcPlan, r: StageResult) -> list[list[Any]]:
    """Stage ``m``'s photon-transfer table (the dark level first; photons summed over the stage's
    ``m`` frames; exposure ``m t_int``; the word's bits; the rounding's variance, ``m / 12`` for
    ``m`` quantised reads): ``calibrate`` fits it with the estimator ``ptc`` used."""
    t = m * cfg.timing.t_int_s
    px, bits = plan.lines * plan.columns, cfg.dtdi.beta_bits
    q = stage_quantization_var_dn2(cfg, m)
    rows: list[list[Any]] = [[t, 0.0, r.dark_mean_dn, r.dark_var_dn2, px, bits, q]]
    for p, mean, var in zip(m * r.photons_per_frame, r.mean_dn, r.var_dn2, strict=True):
        rows.append([t, float(p), float(mean), float(var), px, bits, q])
    return rows


def _summary_rows(results: dict[int, StageResult]) -> list[list[Any]]:
    """``ptc_summary.csv``'s rows: one per stage."""
    rows = []
    for m, r in results.items():
        meas = r.measured.summary()
        rows.append([
            m, r.pedestal_dn, r.offset_dn, *[float(meas[c]) for c in SUMMARY_COLUMNS],
            float(r.spatial["dsnu_e"]), float(r.spatial["prnu"]),
        ])
    return rows


def write_ptc(
    out: Path, cfg: BenchConfig, seed: int, plan: PtcPlan, images: PtcImages,
    results: dict[int, StageResult],
) -> dict[str, Any]:
    """Write every file of the run into ``out`` as one set; returns ``ptc_results.json``'s dict."""
    meta = provenance(cfg, seed)
    img_meta = {k: v for k, v in meta.items() if k not in ("config", "versions")}
    summary = _results_json(meta, cfg, plan, results)
    figs = _plots(results)
    files: list[str] = []
    record = {"command": "ptc", **{k: meta[k] for k in ("version", "seed", "config_sha256")}}
    with output_set(out, record) as tmp:
        for m in plan.stages:
            _write_stage(tmp / f"stage_{m:03d}", cfg, m, plan, images, img_meta)
            files.append(f"stage_{m:03d}/emva1288.txt")
            write_csv(tmp / f"stage_{m:03d}" / "ptc_table.csv", list(TABLE_COLUMNS),
                      _table_rows(cfg, m, plan, results[m]), img_meta)
            files.append(f"stage_{m:03d}/ptc_table.csv")
        write_csv(
            tmp / "ptc_levels.csv",
            ["stage", "level", "photons_per_frame", "photons", "mean_dn", "var_dn2", "signal_dn", "snr"],
            _level_rows(plan, results), meta,
        )
        header = ["stage", "pedestal_dn", "offset_dn", *SUMMARY_COLUMNS, "dsnu_e", "prnu"]
        write_csv(tmp / "ptc_summary.csv", header, _summary_rows(results), meta)
        files += ["ptc_levels.csv", "ptc_summary.csv"]
        for name, fig in figs.items():
            write_figure_png(tmp / name, fig, img_meta)
            files.append(name)
        files.append("ptc_results.json")
        summary["files"] = files
        write_json(tmp / "ptc_results.json", summary)
    return summary


def run_ptc(
    cfg: BenchConfig,
    stages: list[int],
    seed: int,
    out: Path,
    *,
    lines: int = DEFAULT_LINES,
    columns: int | None = None,
    log_levels: int = DEFAULT_LOG_LEVELS,
    dense_levels: int = DEFAULT_DENSE_LEVELS,
    spatial_images: int = DEFAULT_SPATIAL_IMAGES,
) -> dict[str, Any]:
    """Photon-transfer series of DTDI stages: plan -> measure -> analyse -> write.

    Parameters
    ----------
    cfg
        Bench config (sensor, timing, DTDI settings are used).
    stages
        DTDI stages to measure, each in ``1 .. sensor.rows``.
    seed
        Seed of the run's one random generator (fixed pattern first, then temporal noise).
    out
        Output folder (written as one set; an earlier bench_sim output there is replaced).
    lines, columns
        Image size ``L x C`` per image (default 64 x min(256, sensor.columns)).
    log_levels, dense_levels
        Level grid (at least 30 log-spaced levels, 3 dense ones per stage).
    spatial_images
        Images in the spatial (DSNU/PRNU) stacks, dark and at 50 % of each stage's saturation.

    Returns
    -------
    dict
        The content of ``ptc_results.json``.

    Raises
    ------
    BenchSimError
        A bad argument (stage outside ``1 .. rows``, ``beta_bits > 16``, negative seed, bad image
        size, ``out`` a file, a foreign non-empty folder or not writable, a run that does not fit
        in memory or on the disk), before anything is computed.
    """
    seed = check_seed(seed)
    plan = plan_ptc(
        cfg, stages, lines=lines, columns=columns, log_levels=log_levels, dense_levels=dense_levels,
        spatial_images=spatial_images,
    )
    estimate = estimate_ptc(plan.stages, plan.levels.size, plan.lines, plan.columns, plan.spatial_images)
    out = preflight(None, out=out, estimate=estimate, render=False)
    images = measure_ptc(cfg, plan, int(seed))
    results = analyse_ptc(cfg, plan, images)
    return write_ptc(out, cfg, int(seed), plan, images, results)


def run_ptc_command(cfg: BenchConfig, stages: str, seed: int, out: Path, *, area: bool = False) -> None:
    """``bench-sim ptc``: the stages' series (:func:`run_ptc`, ``--stages`` as the command line
    gives it), or with ``area`` the area sensor's raw frames
    (:func:`bench_sim.workflows.area_ptc_job.run_area_ptc`; ``--stages`` not used)."""
    if area:
        run_area_ptc(cfg, seed=seed, out=out)
        return
    run_ptc(cfg, stages=list(parse_stages_arg(stages, cfg.sensor.rows)), seed=seed, out=out)
