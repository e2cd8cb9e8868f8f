"""``bench-sim ptc --area``: EMVA 1288 R4 of the area sensor's raw frames through its whole chain
of effects, against the chain's closed forms, as files.

``bench-sim ptc [CONFIG] --area --seed S --out DIR`` runs :func:`run_area_ptc`: the preflight,
:func:`bench_sim.measure.area_ptc.plan_area` -> :func:`~bench_sim.measure.area_ptc.measure_area`
-> :func:`~bench_sim.measure.area_ptc.analyse_area`, then the files, as one output set:

* ``frames.npz``: the raw frames (:mod:`bench_sim.io.frame_stacks`): ``bench-sim calibrate
  DIR/frames.npz`` fits the same sensor from them;
* ``area_results.json``: the measurement (the fit, defect pixels, the two DSNUs, PRNU, row
  noise), every closed-form term of the chain, and the comparison;
* ``area_comparison.csv``: quantity, measured, standard error, predicted, unit, z-score;
* ``defects.csv``: the defect pixels found (row, column, kind, value: the defects effect's
  ``map_file`` format); ``defects.png``: the DSNU and PRNU histograms.

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench_sim.config import BenchConfig
from bench_sim.io import output_set, write_csv, write_figure_png, write_frames_npz, write_json
from bench_sim.measure.area_ptc import analyse_area, compare_area, measure_area, plan_area
from bench_sim.workflows.calibrate_report import defects_figure
from bench_sim.workflows.estimates import estimate_area_ptc
from bench_sim.workflows.output_meta import provenance
from bench_sim.workflows.preflight import check_seed, preflight

__all__ = ["run_area_ptc", "AREA_ROWS", "AREA_COLUMNS", "AREA_HELP"]

#: ``bench-sim ptc --area``'s help
AREA_HELP = (
    "EMVA 1288 of the area sensor's raw frames through its chain of effects (LE, DSNU at 0 s, the dark "
    "current's non-uniformity, defect pixels, row noise) against the chain's closed forms; --stages not used"
)

#: The window of the physical sensor measured (top-left, clamped to the sensor)
AREA_ROWS, AREA_COLUMNS = 64, 128


def run_area_ptc(
    cfg: BenchConfig, seed: int, out: Path, *, rows: int | None = None, columns: int | None = None
) -> dict[str, Any]:
    """Raw-frame EMVA 1288 of the area sensor (module docstring); returns ``area_results.json``'s dict.

    Raises
    ------
    BenchSimError
        A bad seed or window, an output folder that cannot be written, a run that does not fit,
        before anything is computed.
    """
    seed = check_seed(seed)
    plan = plan_area(
        cfg,
        rows=min(rows or AREA_ROWS, cfg.sensor.rows),
        columns=min(columns or AREA_COLUMNS, cfg.sensor.columns),
    )
    frames_n = plan.photons.size * plan.images + plan.dark_exposure_s.size * plan.dark_images
    out = preflight(
        None, out=out, estimate=estimate_area_ptc(plan.rows, plan.columns, frames_n), render=False
    )
    frames = measure_area(cfg, plan, int(seed))
    measured, predicted = analyse_area(cfg, plan, frames)
    comparison = compare_area(measured, predicted)
    meta = provenance(cfg, int(seed))
    img_meta = {k: v for k, v in meta.items() if k not in ("config", "versions")}
    result: dict[str, Any] = {
        **meta,
        "experiment": "ptc --area",
        "window": [plan.rows, plan.columns],
        "t_int_s": plan.t_int_s,
        "photons_per_frame": plan.photons.tolist(),
        "images_per_level": plan.images,
        "dark_exposures_s": plan.dark_exposure_s.tolist(),
        "dark_images": plan.dark_images,
        "measured": measured.summary(),
        "comparison": comparison,
        "predicted": {
            name: {
                "value": t.value,
                "units": t.units,
                "meaning": t.meaning,
                "positions": [list(p) for p in t.positions],
            }
            for name, t in predicted.items()
        },
    }
    record = {"command": "ptc --area", **{k: meta[k] for k in ("version", "seed", "config_sha256")}}
    with output_set(out, record) as tmp:
        write_frames_npz(
            tmp / "frames.npz",
            {
                "exposure_s": [plan.t_int_s] * plan.photons.size,
                "photons_per_pixel": plan.photons,
                "flats": frames.flats,
                "dark_exposure_s": plan.dark_exposure_s,
                "dark_images": frames.darks,
                "bits": cfg.sensor.adc_bits,
                "wavelength_nm": cfg.sensor.wavelength_m * 1e9,
            },
            img_meta,
        )
        cols = ["quantity", "measured", "standard_error", "predicted", "unit", "z"]
        write_csv(
            tmp / "area_comparison.csv",
            cols,
            [[r[c] for c in cols] for r in comparison["quantities"]],
            img_meta,
        )
        write_csv(tmp / "defects.csv", ["row", "column", "kind", "value"], measured.defects.rows(), img_meta)
        files = ["frames.npz", "area_comparison.csv", "defects.csv"]
        if measured.defects.histograms:
            write_figure_png(tmp / "defects.png", defects_figure(measured), img_meta)
            files.append("defects.png")
        result["files"] = [*files, "area_results.json"]
        write_json(tmp / "area_results.json", result)
    return result
