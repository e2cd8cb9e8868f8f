"""A design's plan and where it stands: the checked spec, the tasks, the output folder and its journal.

- :func:`plan_design`: the spec read and checked (:mod:`bench_sim.workflows.design.spec`), every
  point's engine and input files, the output folder and ``--resume``, into a
  :class:`DesignPlan` before any pass runs.
- The journal (:mod:`bench_sim.runtime.journal`): ``points/NNNNNN.json`` per finished point
  (with its candidates' scores in ``points/NNNNNN.npz``, written first, its SHA-256 in the
  record) and ``chain/NNNNNN.json`` per DR measured through the chain. A record whose scores
  are missing or differ from its hash counts as not done.
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
from bench_sim.workflows.design.spec import DesignSpec, load_design_spec
from bench_sim.workflows.simulate import check_inputs

__all__ = [
    "DESIGN_FILES",
    "POINTS",
    "CHAIN",
    "PointTask",
    "DesignPlan",
    "plan_design",
    "points_journal",
    "chain_journal",
    "scores_path",
    "file_sha256",
    "design_sha256",
    "QUICK_DR_LEVELS",
]

#: the journal folders in ``DIR``
POINTS, CHAIN = "points", "chain"
#: everything a design folder may hold (patterns of :mod:`bench_sim.io.ownership`)
DESIGN_FILES = (
    "design.json",
    "candidates.csv",
    "candidates.csv.json",
    "design.nc",
    "report.md",
    "plots/*.png",
    f"{POINTS}/[0-9]*.json",
    f"{POINTS}/[0-9]*.npz",
    f"{CHAIN}/[0-9]*.json",
)
#: lit levels of the chain's DR series with ``quick`` (reproduce's ``--quick``), else the default 40
QUICK_DR_LEVELS = 24


@dataclass(frozen=True)
class PointTask:
    """Everything a worker needs for one point (picklable): its bench at the pass's word, its
    stream, the candidates and whether to measure the sharpness per stage."""

    index: int
    cfg: BenchConfig
    root_seed: int
    stream: int | None  # None: the root seed's own stream (noise = "common")
    space: Any  # bench_sim.measure.design_scores.CandidateSpace
    sharpness: bool
    count_records: bool = False  # its mitsuba_renders counts its shared records' renders


@dataclass(frozen=True)
class DesignPlan:
    """A checked design: spec, point tasks, output folder, what is already done."""

    spec: DesignSpec
    out: Path
    tasks: tuple[PointTask, ...]
    done: dict[int, dict[str, Any]]
    resume: bool
    sha256: str

    @property
    def todo(self) -> list[PointTask]:
        return [t for t in self.tasks if t.index not in self.done]


def design_sha256(spec: DesignSpec) -> str:
    """Hash of what the design computes: the spec and every point's resolved config."""
    body = {k: v for k, v in spec.as_dict().items() if k != "path"}
    body["configs"] = [config_sha256(p.cfg) for p in spec.points]
    return sha256_text(json.dumps(body, sort_keys=True, default=str))


def points_journal(out: str | Path) -> Journal:
    """``points/NNNNNN.json``, indexed by the record's ``point``."""
    return Journal(Path(out) / POINTS, key="point", digits=6)


def chain_journal(out: str | Path) -> Journal:
    """``chain/NNNNNN.json``, indexed by the record's ``task``."""
    return Journal(Path(out) / CHAIN, key="task", digits=6)


def scores_path(out: str | Path, index: int) -> Path:
    """The scores of point ``index``: ``points/NNNNNN.npz``."""
    return Path(out) / POINTS / f"{int(index):06d}.npz"


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def _check_points(spec: DesignSpec) -> None:
    """Every point's engine and input files, one line naming the point on the first problem."""
    for p in spec.points:
        try:
            if p.cfg.render.engine == "fast":
                check_fast_engine_valid(p.cfg)
            check_inputs(p.cfg)
        except BenchSimError as exc:
            raise BenchSimError(
                f"design spec {spec.path} point {p.index}: {str(exc).splitlines()[0]}"
            ) from None


def _own_points(out: Path, sha: str) -> dict[int, dict[str, Any]]:
    """The finished point records of ``out`` whose scores are there and whole; a record of
    another spec is refused (never overwritten)."""
    own = {}
    for i, rec in points_journal(out).read().items():
        if rec.get("design_sha256") != sha:
            raise BenchSimError(
                f"--out = {str(out)!r}: {POINTS}/{i:06d}.json is a point record of another design spec; "
                "--resume never overwrites a record: use the spec that made it, or a new folder"
            )
        if rec.get("status") != "ok":
            continue
        path = scores_path(out, i)
        try:
            whole = path.is_file() and file_sha256(path) == rec.get("scores_sha256")
        except OSError:
            whole = False
        if whole:
            own[i] = rec
        else:
            warnings.warn(
                f"bench_sim: {path}: missing or not the scores its record names: point {i} is recomputed",
                RuntimeWarning,
                stacklevel=3,
            )
    return own


def _done_points(out: Path, sha: str, resume: bool) -> dict[int, dict[str, Any]]:
    """The points finished in ``out`` (``--resume``), after checking the folder (every entry a
    design's, :data:`DESIGN_FILES`, of this spec)."""
    unfinished = (out / "design.json").is_file() and not (out / OUTPUT_MARKER).is_file()
    if resume and out.is_dir() and any(out.iterdir()):
        refuse_foreign(out, "--out", DESIGN_FILES)
        try:
            old = json.loads((out / "design.json").read_text())
        except (OSError, ValueError):
            old = None
        if old is None and not points_journal(out).read():
            raise BenchSimError(
                f"--out = {str(out)!r}: --resume needs a design folder (no design.json and no "
                "point record there)"
            )
        if isinstance(old, dict) and old.get("design_sha256") != sha:
            raise BenchSimError(
                f"--out = {str(out)!r}: holds a design of another spec or base config (design_sha256 "
                f"{str(old.get('design_sha256'))[:12]} != {sha[:12]}): --resume needs the same spec"
            )
        return _own_points(out, sha)
    if unfinished:
        raise BenchSimError(
            f"--out = {str(out)!r}: holds an unfinished design: add --resume to finish it, or "
            "choose another folder"
        )
    check_output_dir(out)
    return {}


def plan_design(spec_path: str | Path, out: str | Path, *, resume: bool = False) -> DesignPlan:
    """Check everything before any pass runs; one :class:`BenchSimError` line on the first problem."""
    spec = load_design_spec(spec_path)
    _check_points(spec)
    out = Path(out).expanduser().resolve()
    sha = design_sha256(spec)
    done = _done_points(out, sha, resume)
    sharp = "mtf50_along" in spec.objectives
    tasks = tuple(
        PointTask(p.index, p.cfg, spec.seed, None if spec.noise == "common" else p.index, spec.space, sharp)
        for p in spec.points
    )
    return DesignPlan(spec, out, tasks, done, resume, sha)
