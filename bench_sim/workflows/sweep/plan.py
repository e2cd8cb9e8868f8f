"""What a sweep computes and where it stands: the columns of a point, the checked plan, the journal.

Both the run (:mod:`bench_sim.workflows.sweep.run`) and the outputs
(:mod:`bench_sim.workflows.sweep.report`) read the data here; neither imports the other's module.

- :data:`COLUMNS`: the metric columns of a point, with units, kind and meaning.
- :func:`plan_sweep`: the spec read and checked (every point's engine and input files, the
  output folder, ``--resume``) into a :class:`SweepPlan` before any point runs.
- The journal ``points/NNNNNN.json`` (:mod:`bench_sim.runtime.journal`): one record per finished
  point, read back by :func:`read_points`.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench_sim.config import BenchConfig, config_sha256
from bench_sim.errors import BenchSimError
from bench_sim.io import OUTPUT_MARKER, check_output_dir, sha256_text
from bench_sim.io.ownership import refuse_foreign
from bench_sim.render.engines import check_fast_engine_valid
from bench_sim.runtime.journal import Journal
from bench_sim.workflows.simulate import check_inputs
from bench_sim.workflows.sweep.point_images import IMAGES_DIR
from bench_sim.workflows.sweep.spec import SweepSpec, load_spec

__all__ = [
    "COLUMNS",
    "CAMERA",
    "SCENE",
    "RUN",
    "IMAGES",
    "BANDING_DOC",
    "JOURNAL",
    "SWEEP_FILES",
    "PointTask",
    "SweepPlan",
    "banding_column",
    "column_docs",
    "journal",
    "own_points",
    "plan_sweep",
    "read_points",
    "spec_sha256",
]

CAMERA, SCENE, RUN = "camera", "scene", "run"
#: The images a point measures: each is a key of the pass metrics and of the chain DR, and the
#: suffix of its columns (``dr_db_gamma_hdr``, ``snr_darkest_gamma1``, ...)
IMAGES = ("gamma1", "gamma2", "gamma_hdr")

#: The metric columns of a point: name -> (units, kind, meaning). ``camera``: a property of the
#: sensor, timing, DTDI and fusion settings (the same under any light); ``scene``: depends on
#: the lights and the target as much as on the camera; ``run``: how the point ran.
COLUMNS: dict[str, tuple[str, str, str]] = {
    "dr_db_gamma1": ("dB", CAMERA, "measured DR of Gamma1 through the chain (EMVA 1288)"),
    "dr_db_gamma2": ("dB", CAMERA, "measured DR of Gamma2 through the chain (EMVA 1288)"),
    "dr_db_gamma_hdr": ("dB", CAMERA, "measured DR of Gamma_HDR through the chain (EMVA 1288)"),
    "gain_db_vs_gamma1": ("dB", CAMERA, "DR(Gamma_HDR) - DR(Gamma1)"),
    "gain_db_vs_gamma2": ("dB", CAMERA, "DR(Gamma_HDR) - DR(Gamma2)"),
    "eq15_db": ("dB", CAMERA, "eq. 15: 20 lg(mu2 / mu1)"),
    "gain_db_vs_gamma2_extrapolated": ("dB", CAMERA, "gain over Gamma2 with the extrapolated "
                                       "saturation points (the clip points eq. 15 is about)"),
    "eq15_error_db": ("dB", CAMERA, "gain over Gamma2 (extrapolated saturation) minus eq. 15"),
    "eq15_by_construction": ("1", CAMERA, "both stages clip on the output word with one offset: "
                             "the gain over Gamma2 is eq. 15 by construction"),
    "scene_range_db": ("dB", SCENE, "range of the wedge as lit: 20 lg(brightest / darkest step)"),
    "captured_range_db_gamma1": ("dB", SCENE, "range of the wedge steps Gamma1 renders (SNR >= 3, "
                                 "under half clipped)"),
    "captured_range_db_gamma2": ("dB", SCENE, "range of the wedge steps Gamma2 renders"),
    "captured_range_db_gamma_hdr": ("dB", SCENE, "range of the wedge steps Gamma_HDR renders"),
    "captured_gain_db_vs_gamma1": ("dB", SCENE, "captured range of Gamma_HDR minus that of Gamma1 (in "
                                   "steps of the wedge)"),
    "saturated_fraction_gamma1": ("1", SCENE, "pixels of Gamma1 at the word's top"),
    "saturated_fraction_gamma2": ("1", SCENE, "pixels of Gamma2 at the word's top"),
    "saturated_fraction_gamma_hdr": ("1", SCENE, "pixels of Gamma_HDR taken from a clipped Gamma1"),
    "clipped_fraction_gamma1": ("1", SCENE, "pixels of Gamma1 clipped anywhere: a read at full well or "
                                "the ADC top, or the word at its top"),
    "clipped_fraction_gamma2": ("1", SCENE, "pixels of Gamma2 clipped anywhere in the chain"),
    "clipped_fraction_gamma_hdr": ("1", SCENE, "pixels of Gamma_HDR clipped in the stage they come from"),
    "darkest_patch": ("1", SCENE, "the wedge step with the lowest Gamma_HDR"),
    "darkest_reflectance": ("1", SCENE, "its reflectance"),
    "snr_darkest_gamma1": ("1", SCENE, "spatial SNR of the darkest step in Gamma1"),
    "snr_darkest_gamma2": ("1", SCENE, "spatial SNR of the darkest step in Gamma2"),
    "snr_darkest_gamma_hdr": ("1", SCENE, "spatial SNR of the darkest step in Gamma_HDR"),
    "brightest_patch": ("1", SCENE, "the wedge step with the highest Gamma_HDR"),
    "brightest_reflectance": ("1", SCENE, "its reflectance"),
    "snr_brightest_gamma1": ("1", SCENE, "spatial SNR of the brightest step in Gamma1 (empty: over half "
                             "of it clipped)"),
    "snr_brightest_gamma2": ("1", SCENE, "spatial SNR of the brightest step in Gamma2 (empty: clipped)"),
    "snr_brightest_gamma_hdr": ("1", SCENE, "spatial SNR of the brightest step in Gamma_HDR (empty: "
                                "clipped)"),
    "omega_gamma1": ("1", SCENE, "eq. 17 omega of Gamma1"),
    "omega_gamma2": ("1", SCENE, "eq. 17 omega of Gamma2"),
    "omega_gamma_hdr": ("1", SCENE, "eq. 17 omega of Gamma_HDR"),
    "eq18_holds": ("1", SCENE, "eq. 18: omega(HDR) < min(omega1, omega2)"),
    "spot_fill_ratio": ("1", SCENE, "lights.strong / lights.weak irradiance (empty unless both emit)"),
    "no_patches": ("1", SCENE, "why the patch metrics are empty (no wedge in view)"),
    "mtf50_along_gamma1": ("cycles/px", SCENE, "ISO 12233 e-SFR MTF50 along the track (lines) of Gamma1, "
                           "mean over the slanted edges (empty: no slanted_edges target, or clipped)"),
    "mtf50_along_gamma2": ("cycles/px", SCENE, "MTF50 along the track of Gamma2 (stage mu2)"),
    "mtf50_along_gamma_hdr": ("cycles/px", SCENE, "MTF50 along the track of Gamma_HDR"),
    "mtf50_across_gamma1": ("cycles/px", SCENE, "MTF50 across the track (columns) of Gamma1"),
    "mtf50_across_gamma2": ("cycles/px", SCENE, "MTF50 across the track of Gamma2"),
    "mtf50_across_gamma_hdr": ("cycles/px", SCENE, "MTF50 across the track of Gamma_HDR"),
    "mitsuba_renders": ("1", RUN, "Mitsuba renders this point's pass made"),
}
#: Gamma_HDR against its exact truth (:mod:`bench_sim.measure.fusion_scores`): per rule and region
TRUTH_RULES = ("eq11", "clip")
TRUTH_REGIONS = ("whole", "spot", "fill", "spot_edge")
COLUMNS.update({
    f"truth_{stat}_{rule}_{region}": (
        "1", SCENE, f"{'mean' if stat == 'bias' else 'RMS'} relative error of Gamma_HDR by rule "
        f"{rule!r} against its exact truth, region {region!r}",
    )
    for rule in TRUTH_RULES for region in TRUTH_REGIONS for stat in ("bias", "rms")
})
COLUMNS.update({
    f"from_clipped_fraction_{rule}": (
        "1", SCENE, f"pixels of Gamma_HDR by rule {rule!r} taken from a clipped stage"
    )
    for rule in TRUTH_RULES
})
COLUMNS["tdi_light_ratio_outside_fraction"] = (
    "1", SCENE, "pixels whose TDI-window light ratio (per row over mu2 rows / over mu1 rows) leaves 1 +- 0.05"
)
COLUMNS["tdi_light_ratio_p99"] = ("1", SCENE, "99th percentile of the TDI-window light ratio")
#: The column of a spec's ``ratio = [a, b]`` (:mod:`bench_sim.workflows.sweep.light_keys`)
RATIO_DOC = ("1", SCENE, "irradiance of the spec's ratio lights, first / second (empty unless both emit)")
#: Banding columns (one per flickering light and stage): ``banding_<light>_stage_<m>``.
BANDING_DOC = ("1", SCENE, "flicker banding along the track: amplitude at the light's frequency "
               "relative to the mean, of the stage's noise-free illumination on the flat-target pixels "
               "(bench_sim.metrics.banding.flat_banding; NaN on a target without flat areas)")
#: The journal's folder in ``DIR``: one ``NNNNNN.json`` record per finished point
JOURNAL = "points"
#: Everything a sweep folder may hold (patterns of :mod:`bench_sim.io.ownership`): a folder
#: holding anything else is not a sweep's, and ``--resume`` refuses it
SWEEP_FILES = (
    "sweep.json", "points.csv", "points.csv.json", "points_images.csv", "sweep.nc", "report.md",
    "plots/*.png", f"{JOURNAL}/[0-9]*.json", f"{IMAGES_DIR}/point_*.zarr/**",
)


def banding_column(light: str, stage: int) -> str:
    """The banding column of a flickering light at a stage."""
    return f"banding_{light}_stage_{stage:03d}"


@dataclass(frozen=True)
class PointTask:
    """Everything a worker needs for one point (picklable)."""

    index: int
    cfg: BenchConfig
    root_seed: int
    stream: int
    stages: tuple[int, ...]
    dr_levels: int
    flicker_lights: tuple[str, ...]
    banding_stages: tuple[int, ...] = ()  # the spec's stages (points_images.csv)
    ratio: tuple[str, str] | None = None  # the spec's light pair (light_ratio)
    images_dir: str | None = None  # keep_images: DIR/images (bench_sim.workflows.sweep.point_images)
    count_records: bool = False  # its mitsuba_renders counts its shared records' renders (run.py)


@dataclass(frozen=True)
class SweepPlan:
    """A checked sweep: spec, tasks, output folder and what is already done."""

    spec: SweepSpec
    out: Path
    tasks: tuple[PointTask, ...]
    done: dict[int, dict[str, Any]]
    resume: bool
    sha256: str
    columns: tuple[str, ...]

    @property
    def todo(self) -> list[PointTask]:
        return [t for t in self.tasks if t.index not in self.done]


def column_docs(plan: SweepPlan) -> dict[str, tuple[str, str, str]]:
    """Every metric column of the plan -> (units, kind, meaning)."""
    return {c: {**COLUMNS, "light_ratio": RATIO_DOC}.get(c, BANDING_DOC) for c in plan.columns}


def spec_sha256(spec: SweepSpec) -> str:
    """Hash of what the points compute: the spec and every point's resolved config."""
    body = {k: v for k, v in spec.as_dict().items() if k != "path"}
    body["configs"] = [config_sha256(p.cfg) for p in spec.points]
    return sha256_text(json.dumps(body, sort_keys=True, default=str))


def _point_stages(cfg: BenchConfig, flicker: bool) -> tuple[int, ...]:
    """Stages of a point's pass: the fused pair, and stage 1 when a light flickers (banding)."""
    return tuple(sorted({cfg.fusion.mu1, cfg.fusion.mu2} | ({1} if flicker else set())))


def journal(out: str | Path) -> Journal:
    """The journal of a sweep folder: ``points/NNNNNN.json``, indexed by the record's ``point``."""
    return Journal(Path(out) / JOURNAL, key="point", digits=6)


def read_points(out: str | Path) -> dict[int, dict[str, Any]]:
    """The point records of a sweep folder (``points/NNNNNN.json``): index -> record. An
    unreadable record counts as not done (:mod:`bench_sim.runtime.journal`)."""
    return journal(out).read()


def _unfinished_sweep(out: Path) -> bool:
    return (out / "sweep.json").is_file() and not (out / OUTPUT_MARKER).is_file()


def _check_points(spec: SweepSpec) -> None:
    """Every point's engine and input files, one line naming the point on the first problem."""
    for p in spec.points:
        where = f"sweep spec {spec.path} point {p.index}"
        try:
            if p.cfg.render.engine == "fast":
                check_fast_engine_valid(p.cfg)
            check_inputs(p.cfg)
        except BenchSimError as exc:
            raise BenchSimError(f"{where}: {str(exc).splitlines()[0]}") from None


def _sweep_meta(out: Path) -> dict[str, Any] | None:
    """``sweep.json`` of a sweep folder; ``None`` (one warning) if it is missing, empty or
    unreadable (a crash while it was written, a lost file): the records, which carry their
    spec's hash and seed, decide then, and it is rebuilt from them."""
    try:
        meta = json.loads((out / "sweep.json").read_text())
        if isinstance(meta, dict):
            return meta
    except (OSError, ValueError):
        pass
    warnings.warn(f"bench_sim: {out / 'sweep.json'}: missing, empty or unreadable: rebuilt from the point "
                  "records, which are checked one by one", RuntimeWarning, stacklevel=3)
    return None


def own_points(out: Path, sha: str, seed: int) -> dict[int, dict[str, Any]]:
    """The finished (``ok``) point records of ``out``, every one of which must belong to this
    sweep (same spec hash and seed): a record of another spec or seed is never overwritten, so
    ``--resume`` is refused (one line naming it). An unreadable record is not a record: its
    point runs again (:mod:`bench_sim.runtime.journal`)."""
    own = {}
    for i, rec in read_points(out).items():
        if rec.get("spec_sha256") != sha or rec.get("seed") != seed:
            raise BenchSimError(
                f"--out = {str(out)!r}: {JOURNAL}/{i:06d}.json is a point record of another spec or seed; "
                "--resume never overwrites a record: use the spec and seed that made it, or a new folder"
            )
        if rec.get("status") == "ok":
            own[i] = rec
    return own


def _done_points(out: Path, sha: str, seed: int, resume: bool) -> dict[int, dict[str, Any]]:
    """The points already finished in ``out`` (``--resume``), after checking the folder: with
    ``--resume`` every entry of it must be a sweep's (:data:`SWEEP_FILES`), its ``sweep.json``
    of this spec, or, where that is lost, its records of this spec (then rebuilt from them)."""
    if resume and out.is_dir() and any(out.iterdir()):
        refuse_foreign(out, "--out", SWEEP_FILES)
        if not (out / "sweep.json").exists() and not read_points(out):
            raise BenchSimError(
                f"--out = {str(out)!r}: --resume needs a sweep folder (no sweep.json and no point record "
                "there)"
            )
        old = _sweep_meta(out)
        if old is not None and old.get("spec_sha256") != sha:
            raise BenchSimError(
                f"--out = {str(out)!r}: holds a sweep of another spec or base config "
                f"(spec_sha256 {str(old.get('spec_sha256'))[:12]} != {sha[:12]}): --resume needs the "
                "same spec"
            )
        return own_points(out, sha, seed)
    if _unfinished_sweep(out):
        raise BenchSimError(
            f"--out = {str(out)!r}: holds an unfinished sweep: add --resume to finish it, or choose "
            "another folder"
        )
    check_output_dir(out)
    return {}


def plan_sweep(spec_path: str | Path, out: str | Path, *, resume: bool = False) -> SweepPlan:
    """Check everything before any point runs (see :mod:`bench_sim.workflows.sweep.run`); raises
    :class:`~bench_sim.errors.BenchSimError` with one line on the first problem."""
    spec = load_spec(spec_path)
    _check_points(spec)
    out = Path(out).expanduser().resolve()
    sha = spec_sha256(spec)
    done = _done_points(out, sha, spec.seed, resume)
    flicker = tuple(sorted({n for p in spec.points for n, light in p.cfg.lights.items() if light.flickers}))
    quick_levels = 24 if spec.quick else 40
    tasks = tuple(
        PointTask(
            index=p.index,
            cfg=p.cfg,
            root_seed=spec.seed,
            stream=0 if spec.noise == "common" else p.index,
            stages=tuple(sorted({*_point_stages(p.cfg, bool(flicker)), *spec.stages})),
            dr_levels=quick_levels,
            flicker_lights=flicker,
            banding_stages=spec.stages,
            ratio=spec.ratio,
            images_dir=str(out / IMAGES_DIR) if spec.keep_images else None,
        )
        for p in spec.points
    )
    stages = sorted({m for t in tasks for m in t.stages})
    columns = (*COLUMNS, *(["light_ratio"] if spec.ratio else []),
               *(banding_column(n, m) for n in flicker for m in stages))
    return SweepPlan(spec, out, tasks, done, resume, sha, columns)
