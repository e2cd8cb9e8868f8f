"""Photon-transfer measurement (EMVA 1288 R4) of DTDI stages, through the real sensor + DTDI code.

``bench-sim ptc [CONFIG] --stages 1,10,80 --seed S --out DIR`` runs :func:`run_ptc`.

Measurement
-----------
A uniform field of ``mu_p`` photons per pixel per frame is exposed through the EMVA 1288 pixel
model and the streaming DTDI accumulator (:func:`bench_sim.sensor.pipeline.sensor_dtdi_pass`),
with the config's sensor, timing and DTDI settings. One pass of ``K = 2 L + max(stages) - 1``
frames over the top-left ``max(stages)`` rows x ``C`` columns of the sensor gives, for every
requested stage, ``2 L`` complete lines: lines ``0 .. L-1`` are image A, lines ``L .. 2L-1`` image
B (their temporal noise is independent: every line sums different pixel reads). The default
image is ``L = 64`` lines x ``C = 256`` columns (or the sensor's width if smaller); one pass per
level, so the whole series runs in seconds.

Levels (mean photons per pixel per frame): a dark level, ``log_levels`` log-spaced levels from
well below SNR = 1 of the highest stage to 1.5 x the saturation of the lowest stage, plus
``dense_levels`` levels from 0.90 to 1.02 x the predicted saturation of every requested stage
(the prediction is the closed-form model; it only places the levels, the analysis uses the
images). Every stage sees every level. For stage ``m`` the descriptor's photon count is the
mean number of photons per pixel summed over the ``m`` frames that make the stage value
(``m * mu_p``) and its exposure time is ``m * t_int``.

Spatial stacks (DSNU, PRNU; the EMVA reference package needs them): ``spatial_images`` (16)
images in the dark and at 50 % of each stage's predicted saturation, consecutive line blocks
of one pass each. In a DTDI stage every line sums the same ``m`` pixels of its column, so the
fixed pattern is a column pattern.

Pedestal
--------
EMVA 1288 needs the dark signal unclipped. With ``dtdi.subtract_black = true`` a stage's dark
value sits at 0 DN and would be clipped by the output word (values below 0 are stored as 0), so
the measurement adds a pedestal ``P_m`` [DN] to stage ``m``: ``ceil(5 sigma)`` of its dark
signal's spread (temporal noise, DSNU and the column offsets, which add coherently over the
``m`` rows), less the accumulated black offset ``m * b`` when ``subtract_black`` is false. The
pedestal lowers the usable range of stage ``m`` by ``P_m`` DN (reported per stage).

Files (DIR)
-----------
* ``stage_MMM/emva1288.txt``: EMVA 1288 descriptor (``n bits width height``; per level
  ``b exposure_ns photons`` and its two ``i images/...tif`` lines; ``d exposure_ns`` and the
  dark pair; then the spatial stacks, a ``b`` and a ``d`` line with ``spatial_images`` ``i``
  lines each), read by the ``emva1288`` reference package; images are 16-bit TIFF. A 16-bit
  file holds the ``beta``-bit stage word only for ``beta <= 16``: a config with
  ``dtdi.beta_bits > 16`` is refused with a clear error.
* ``ptc_results.json``: per stage K, dark temporal noise, saturation capacity, SNR curve,
  dynamic range (measured and model), the expected values from the config, and the series.
* ``ptc_levels.csv`` (every level of every stage), ``ptc_summary.csv`` (one row per stage).
* ``ptc.png`` (photon transfer: variance vs mean), ``snr.png`` (SNR vs photons per frame).

Every file carries the config (or its SHA-256 where a full copy does not fit), the seed and the
bench_sim version; every file is written atomically after the whole series has been computed.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

import bench_sim
from bench_sim.config import BenchConfig, config_sha256, config_to_toml_dict
from bench_sim.errors import BenchSimError
from bench_sim.io import atomic_path, write_json, write_tiff16
from bench_sim.metrics.emva1288 import (
    analyse_photon_transfer,
    dynamic_range_from_series,
    mean_var_from_pair,
    snr_curve,
    spatial_nonuniformity,
)
from bench_sim.sensor.dtdi import validate_stages
from bench_sim.sensor.emva import draw_fixed_pattern
from bench_sim.sensor.model import (
    QUANTIZATION_VAR_DN2,
    dark_noise_e,
    stage_dark_std_dn,
    stage_mean_var_dn,
    stage_saturation_photons,
    stage_snr1_photons,
)
from bench_sim.sensor.pipeline import sensor_dtdi_pass

__all__ = [
    "run_ptc",
    "plan_levels",
    "ptc_pedestals",
    "DEFAULT_LINES",
    "DEFAULT_COLUMNS",
    "DEFAULT_LOG_LEVELS",
    "DEFAULT_DENSE_LEVELS",
    "DEFAULT_SPATIAL_IMAGES",
]

DEFAULT_LINES = 64
DEFAULT_COLUMNS = 256
DEFAULT_LOG_LEVELS = 32
DEFAULT_DENSE_LEVELS = 13
DEFAULT_SPATIAL_IMAGES = 16
#: Dense levels near each stage's predicted saturation, as fractions of it (the variance peaks
#: a few per cent below the clip; 13 levels give 1 % steps).
DENSE_FROM, DENSE_TO = 0.90, 1.02
#: EMVA files hold 16-bit images.
MAX_FILE_BITS = 16


def ptc_pedestals(cfg: BenchConfig, stages: tuple[int, ...]) -> dict[int, int]:
    """Pedestal [DN] per stage that keeps the dark signal 5 sigma above 0 (see module doc)."""
    out: dict[int, int] = {}
    b = cfg.sensor.black_offset_dn
    for m in stages:
        need = 5.0 * stage_dark_std_dn(cfg.sensor, cfg.timing.t_int_s, m) + 1.0
        if not cfg.dtdi.subtract_black:
            need -= m * b
        out[m] = max(0, math.ceil(need))
    return out


def _stage_saturation_photons(cfg: BenchConfig, stage: int, pedestal_dn: float) -> float:
    return stage_saturation_photons(
        cfg.sensor, cfg.timing.t_int_s, stage, beta_bits=cfg.dtdi.beta_bits,
        subtract_black=cfg.dtdi.subtract_black, pedestal_dn=pedestal_dn,
    )


def plan_levels(
    cfg: BenchConfig,
    stages: tuple[int, ...],
    pedestals: dict[int, int],
    log_levels: int = DEFAULT_LOG_LEVELS,
    dense_levels: int = DEFAULT_DENSE_LEVELS,
) -> np.ndarray:
    """Bright levels [mean photons per pixel per frame], increasing (the dark level excluded).

    ``log_levels`` log-spaced levels from 0.25 x the SNR = 1 level of the highest stage to
    1.5 x the saturation of the lowest stage, and ``dense_levels`` from 0.90 to 1.02 x each
    stage's predicted saturation. Levels closer than 0.5 % are merged.
    """
    p_sat = {m: _stage_saturation_photons(cfg, m, pedestals[m]) for m in stages}
    p_lo = 0.25 * min(stage_snr1_photons(cfg.sensor, cfg.timing.t_int_s, m) for m in stages)
    p_hi = 1.5 * max(p_sat.values())
    grid = [np.geomspace(p_lo, p_hi, log_levels)]
    for m in stages:
        grid.append(p_sat[m] * np.linspace(DENSE_FROM, DENSE_TO, dense_levels))
    levels = np.unique(np.concatenate(grid))
    keep = [float(levels[0])]
    for v in levels[1:]:
        if v > keep[-1] * 1.005:
            keep.append(float(v))
    return np.asarray(keep)


def _validate(
    cfg: BenchConfig, stages: list[int], seed: int, out: Path, lines: int, columns: int | None,
    log_levels: int, dense_levels: int, spatial_images: int,
) -> tuple[tuple[int, ...], int]:
    st = validate_stages(stages, cfg.sensor.rows)
    if not isinstance(seed, int | np.integer) or isinstance(seed, bool) or seed < 0:
        raise BenchSimError(f"--seed = {seed!r}: must be an integer >= 0")
    if cfg.dtdi.beta_bits > MAX_FILE_BITS:
        raise BenchSimError(
            f"dtdi.beta_bits = {cfg.dtdi.beta_bits}: EMVA 1288 image files are 16-bit, so the "
            f"photon-transfer export needs beta_bits <= {MAX_FILE_BITS}"
        )
    if not 4 <= int(lines) <= 4096:
        raise BenchSimError(f"lines = {lines!r}: image height must lie in 4..4096")
    cols = min(DEFAULT_COLUMNS, cfg.sensor.columns) if columns is None else int(columns)
    if not 4 <= cols <= cfg.sensor.columns:
        raise BenchSimError(f"columns = {columns!r}: image width must lie in 4..{cfg.sensor.columns}")
    if log_levels < 30:
        raise BenchSimError(f"log_levels = {log_levels!r}: EMVA 1288 needs at least 30 levels")
    if dense_levels < 3:
        raise BenchSimError(f"dense_levels = {dense_levels!r}: need at least 3 near saturation")
    if spatial_images < 3:
        raise BenchSimError(f"spatial_images = {spatial_images!r}: EMVA spatial stacks need >= 3")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise BenchSimError(f"--out = {str(out)!r}: exists and is not a folder")
    return st, cols


def _metadata(cfg: BenchConfig, seed: int) -> dict[str, Any]:
    return {
        "bench_sim_version": bench_sim.__version__,
        "seed": int(seed),
        "config_sha256": config_sha256(cfg),
        "config": config_to_toml_dict(cfg),
    }


def _descriptor_text(
    stage: int, bits: int, width: int, height: int, exposure_ns: float,
    bright: list[tuple[float, list[str]]], dark: list[list[str]], meta: dict[str, Any],
) -> str:
    """EMVA 1288 descriptor: ``n bits width height``; ``b exposure_ns photons`` / ``d exposure_ns``
    each followed by its ``i path`` lines (2 images: temporal set; more: spatial set)."""
    lines = [
        f"# EMVA 1288 descriptor: bench_sim photon-transfer series of DTDI stage {stage}",
        f"# bench_sim {meta['bench_sim_version']}  seed {meta['seed']}  "
        f"config_sha256 {meta['config_sha256']}",
        "# photons: mean photons per pixel summed over the stage's frames; exposure: ns",
        "# config: " + json.dumps(meta["config"], sort_keys=True),
        "v 4.0",
        f"n {bits} {width} {height}",
    ]
    for photons, names in bright:
        lines.append(f"b {exposure_ns:.3f} {photons:.9g}")
        lines += [f"i {n}" for n in names]
    for names in dark:
        lines.append(f"d {exposure_ns:.3f}")
        lines += [f"i {n}" for n in names]
    return "\n".join(lines) + "\n"


def _csv_text(header: list[str], rows: list[list[Any]], meta: dict[str, Any]) -> str:
    buf = io.StringIO()
    buf.write(
        f"# bench_sim {meta['bench_sim_version']} seed={meta['seed']} "
        f"config_sha256={meta['config_sha256']}\n"
    )
    buf.write("# config: " + json.dumps(meta["config"], sort_keys=True) + "\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in r])
    return buf.getvalue()


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _plots(results: dict[int, dict[str, Any]], meta: dict[str, Any]) -> dict[str, bytes]:
    """The PTC and SNR plots as PNG bytes (rendered before anything is written)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    png_meta = {
        "Software": f"bench_sim {meta['bench_sim_version']}",
        "Description": json.dumps(
            {"seed": meta["seed"], "config_sha256": meta["config_sha256"], "config": meta["config"]},
            sort_keys=True,
        ),
    }
    written: dict[str, bytes] = {}

    def _png(fig: Any) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, metadata=png_meta)
        plt.close(fig)
        return buf.getvalue()

    fig, ax = plt.subplots(figsize=(7, 5))
    for m, r in results.items():
        sig = np.asarray(r["series"]["signal_dn"])
        var = np.asarray(r["series"]["var_dn2"]) - r["dark"]["var_dn2"]
        ok = (sig > 0) & (var > 0)
        (line,) = ax.loglog(sig[ok], var[ok], "o", ms=3, label=f"stage {m}")
        k = r["measured"]["K_dn_per_e"]
        xs = np.geomspace(max(sig[ok].min(), 1e-3), r["measured"]["saturation_signal_dn"], 50)
        ax.loglog(xs, k * xs, "-", color=line.get_color(), lw=0.8)
    ax.set_xlabel(r"$\mu_y - \mu_{y.dark}$ [DN]")
    ax.set_ylabel(r"$\sigma_y^2 - \sigma_{y.dark}^2$ [DN$^2$]")
    ax.set_title("Photon transfer (lines: fitted K)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    written["ptc.png"] = _png(fig)

    fig, ax = plt.subplots(figsize=(7, 5))
    for m, r in results.items():
        p = np.asarray(r["series"]["photons_per_frame"])
        snr = np.array([np.nan if x is None else x for x in r["series"]["snr"]], dtype=np.float64)
        i_sat = r["measured"]["saturation_level_index"]
        ok = np.isfinite(snr) & (snr > 0)
        ok[i_sat + 1 :] = False
        (line,) = ax.loglog(p[ok], snr[ok], "o", ms=3, label=f"stage {m}")
        model = np.asarray(r["series"]["snr_model"])
        ax.loglog(p[ok], model[ok], "-", color=line.get_color(), lw=0.8)
    ax.axhline(1.0, color="k", lw=0.5)
    ax.set_xlabel(r"$\mu_p$ per frame [photons/pixel]")
    ax.set_ylabel("SNR")
    ax.set_title("SNR vs irradiation (lines: linear model)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend()
    written["snr.png"] = _png(fig)
    return written


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
    """Photon-transfer series of DTDI stages, EMVA 1288 files and bench_sim's own results.

    Parameters
    ----------
    cfg
        Bench config (sensor, timing, DTDI settings are used).
    stages
        DTDI stages to measure, each in ``1 .. sensor.rows``.
    seed
        Seed of the run's one random generator (fixed pattern first, then temporal noise).
    out
        Output folder (created; files of an earlier run in it are replaced).
    lines, columns
        Image size ``L x C`` per image (default 64 x min(256, sensor.columns)).
    log_levels, dense_levels
        Level grid (see :func:`plan_levels`; at least 30 log-spaced levels).
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
        size, ``out`` an existing file), before anything is written.
    """
    out = Path(out)
    st, cols = _validate(
        cfg, stages, seed, out, lines, columns, log_levels, dense_levels, spatial_images
    )
    sensor = cfg.sensor
    t_int_s = cfg.timing.t_int_s
    m_max = st[-1]
    n_lines = int(lines)
    n_spatial = int(spatial_images)
    pedestals = ptc_pedestals(cfg, st)
    levels = plan_levels(cfg, st, pedestals, log_levels, dense_levels)
    all_levels = np.concatenate([[0.0], levels])  # level 0 = dark
    n_frames = 2 * n_lines + m_max - 1
    meta = _metadata(cfg, seed)

    rng = np.random.default_rng(seed)
    fixed = draw_fixed_pattern(sensor, rng).window(m_max, cols)

    def _pass(p: float, rows: int, n_img: int, which: tuple[int, ...]) -> dict[int, np.ndarray]:
        """One uniform-field pass; stage -> (n_img, L, C) images (consecutive line blocks)."""
        frames = n_img * n_lines + max(which) - 1
        photons = np.broadcast_to(np.float64(p), (frames, rows, cols))
        imgs = sensor_dtdi_pass(
            photons, sensor, cfg.dtdi, t_int_s, which, rng, fixed=fixed.window(rows, cols),
            lines=n_img * n_lines, pedestal_dn={m: pedestals[m] for m in which},
        )
        return {m: imgs[m].reshape(n_img, n_lines, cols) for m in which}

    # temporal series: a pair per level, every stage from the same pass
    pairs: dict[int, list[np.ndarray]] = {m: [] for m in st}
    for p in all_levels:
        for m, stack in _pass(float(p), m_max, 2, st).items():
            pairs[m].append(stack)
    # spatial stacks: dark (all stages in one pass), bright at 50 % of each stage's saturation
    spatial_dark = _pass(0.0, m_max, n_spatial, st)
    p50 = {m: 0.5 * _stage_saturation_photons(cfg, m, pedestals[m]) for m in st}
    spatial_bright = {m: _pass(p50[m], m, n_spatial, (m,))[m] for m in st}

    k_cfg = sensor.conversion_gain_dn_per_e
    sigma_d_px_e = dark_noise_e(sensor, t_int_s)
    results: dict[int, dict[str, Any]] = {}
    for m in st:
        # quantisation noise of the stage: m pixel ADC roundings, or one of the output word
        q_var = m * QUANTIZATION_VAR_DN2 if sensor.quantization else QUANTIZATION_VAR_DN2
        mv = np.array([mean_var_from_pair(a, b) for a, b in pairs[m]])
        dark_mean, dark_var = float(mv[0, 0]), float(mv[0, 1])
        mean, var = mv[1:, 0], mv[1:, 1]
        photons_stage = m * levels
        res = analyse_photon_transfer(
            photons_stage, mean, var, dark_mean, dark_var, quantization_var_dn2=q_var
        )
        signal = mean - dark_mean
        std = np.sqrt(np.maximum(var, 0.0))
        snr = snr_curve(signal, std)
        dr_other = {
            meth: dynamic_range_from_series(
                np.concatenate([[0.0], photons_stage]), np.concatenate([[dark_mean], mean]),
                np.concatenate([[math.sqrt(max(dark_var, 0.0))], std]), dark_signal=dark_mean,
                saturation=meth, responsivity=res.responsivity_dn_per_photon,
            ).dr_db
            for meth in ("max_variance", "interpolated", "extrapolated")
        }
        spatial = spatial_nonuniformity(spatial_bright[m], spatial_dark[m], res.k_dn_per_e)
        # linear model of the stage: m independent reads
        mean_model, var_model = stage_mean_var_dn(levels, sensor, t_int_s, m)
        dark_model, dark_var_model = stage_mean_var_dn(0.0, sensor, t_int_s, m)
        snr_model = (mean_model - dark_model) / np.sqrt(var_model)
        expected = {
            "K_dn_per_e": k_cfg,
            "quantum_efficiency": sensor.quantum_efficiency,
            "dark_temporal_noise_e": math.sqrt(m) * sigma_d_px_e,
            "dark_temporal_noise_dn": math.sqrt(float(dark_var_model)),
            "saturation_photons_per_frame": _stage_saturation_photons(cfg, m, pedestals[m]),
        }
        results[m] = {
            "stage": m,
            "exposure_ns": m * t_int_s * 1e9,
            "pedestal_dn": pedestals[m],
            "measured": res.summary(),
            "dynamic_range_db_by_saturation_method": dr_other,
            "spatial": {**spatial, "photons_per_frame": p50[m], "images": n_spatial},
            "per_frame": {
                "photons_sat": res.photons_sat / m,
                "photons_min": res.photons_min / m,
                "photons_min_model": res.photons_min_model / m,
            },
            "expected": expected,
            "relative_error": {
                "K": res.k_dn_per_e / k_cfg - 1.0,
                "dark_temporal_noise_e": (
                    res.dark_temporal_noise_e / expected["dark_temporal_noise_e"] - 1.0
                    if expected["dark_temporal_noise_e"] > 0
                    else None
                ),
                "dark_temporal_noise_dn": (
                    res.dark_temporal_noise_dn / expected["dark_temporal_noise_dn"] - 1.0
                    if expected["dark_temporal_noise_dn"] > 0
                    else None
                ),
            },
            "dark": {"mean_dn": dark_mean, "var_dn2": dark_var},
            "series": {
                "photons_per_frame": levels.tolist(),
                "photons": photons_stage.tolist(),
                "mean_dn": mean.tolist(),
                "var_dn2": var.tolist(),
                "signal_dn": signal.tolist(),
                "snr": [float(x) if np.isfinite(x) else None for x in snr],
                "snr_model": snr_model.tolist(),
            },
        }

    summary: dict[str, Any] = {
        **meta,
        "experiment": "ptc",
        "stages": list(st),
        "image_lines": n_lines,
        "image_columns": cols,
        "frames_per_level": n_frames,
        "t_int_s": t_int_s,
        "beta_bits": cfg.dtdi.beta_bits,
        "subtract_black": cfg.dtdi.subtract_black,
        "levels": len(all_levels),
        "spatial_images": n_spatial,
        "notes": [
            "Two images per level: lines 0..L-1 and L..2L-1 of one DTDI pass of "
            "2L + max(stages) - 1 frames over the top-left max(stages) rows.",
            "photons = mean photons per pixel summed over the m frames of stage m; exposure = "
            "m * t_int.",
            "A pedestal per stage keeps the dark signal unclipped (EMVA 1288); it lowers the "
            "stage's range by pedestal_dn.",
            "Saturation: maximum of the temporal variance, refined between levels (parabola); "
            "dynamic_range_db_by_saturation_method gives the grid maximum (EMVA) and the "
            "linear extrapolation to the clipped plateau as well.",
        ],
        "results": {str(m): r for m, r in results.items()},
    }
    pngs = _plots(results, meta)

    # ---- write (everything computed; each file atomically) ----
    out.mkdir(parents=True, exist_ok=True)
    img_meta = {k: v for k, v in meta.items() if k != "config"}
    files: list[str] = []

    def _save(sdir: Path, name: str, img: np.ndarray, m: int, photons: float, tag: str) -> str:
        write_tiff16(
            sdir / name, img.astype(np.uint16),
            {**img_meta, "stage": m, "photons": photons, "image": tag},
        )
        return name

    for m in st:
        sdir = out / f"stage_{m:03d}"
        bright: list[tuple[float, list[str]]] = []
        dark: list[str] = []
        for idx, stack in enumerate(pairs[m]):
            ph = float(m * all_levels[idx])
            kind = "dark" if idx == 0 else f"bright_{idx:03d}"
            names = [
                _save(sdir, f"images/{kind}_{tag}.tif", img, m, ph, tag)
                for tag, img in zip("ab", stack, strict=True)
            ]
            if idx == 0:
                dark = names
            else:
                bright.append((ph, names))
        ph50 = float(m * p50[m])
        sp_bright = [
            _save(sdir, f"images/spatial_bright_{i:03d}.tif", img, m, ph50, f"spatial {i}")
            for i, img in enumerate(spatial_bright[m])
        ]
        sp_dark = [
            _save(sdir, f"images/spatial_dark_{i:03d}.tif", img, m, 0.0, f"spatial {i}")
            for i, img in enumerate(spatial_dark[m])
        ]
        bright.append((ph50, sp_bright))
        text = _descriptor_text(
            m, cfg.dtdi.beta_bits, cols, n_lines, m * t_int_s * 1e9, bright, [dark, sp_dark], meta
        )
        _write_text(sdir / "emva1288.txt", text)
        files.append(f"stage_{m:03d}/emva1288.txt")

    level_rows = []
    for m, r in results.items():
        s = r["series"]
        level_rows.append([m, 0, 0.0, 0.0, r["dark"]["mean_dn"], r["dark"]["var_dn2"], 0.0, ""])
        for i in range(len(levels)):
            snr_v = s["snr"][i]
            level_rows.append([
                m, i + 1, s["photons_per_frame"][i], s["photons"][i], s["mean_dn"][i],
                s["var_dn2"][i], s["signal_dn"][i], "" if snr_v is None else float(snr_v),
            ])
    _write_text(out / "ptc_levels.csv", _csv_text(
        ["stage", "level", "photons_per_frame", "photons", "mean_dn", "var_dn2", "signal_dn", "snr"],
        level_rows, meta,
    ))
    summary_cols = [
        "K_dn_per_e", "quantum_efficiency", "dark_temporal_noise_dn", "dark_temporal_noise_e",
        "saturation_signal_dn", "saturation_capacity_e", "photons_sat", "photons_min",
        "photons_min_model", "dynamic_range_db", "dynamic_range_db_model", "snr_max",
    ]
    _write_text(out / "ptc_summary.csv", _csv_text(
        ["stage", "pedestal_dn", *summary_cols, "dsnu_e", "prnu"],
        [[m, r["pedestal_dn"], *[float(r["measured"][c]) for c in summary_cols],
          float(r["spatial"]["dsnu_e"]), float(r["spatial"]["prnu"])]
         for m, r in results.items()],
        meta,
    ))
    files += ["ptc_levels.csv", "ptc_summary.csv"]
    for name, data in pngs.items():
        with atomic_path(out / name) as tmp:
            tmp.write_bytes(data)
        files.append(name)
    files.append("ptc_results.json")
    summary["files"] = files
    write_json(out / "ptc_results.json", summary)
    return summary
