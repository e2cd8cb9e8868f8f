"""The inputs of ``bench-sim calibrate``: a photon-transfer table (CSV), EMVA 1288 results
(TOML, or the results XML of the ``emva1288`` package), the raw images of a measurement (a frames
``.npz`` or a folder of images with ``frames.csv``: :mod:`bench_sim.workflows.calibrate_images`)
and an EMVA 1288 descriptor with its images. Each reader checks its file and raises one line
(:class:`~bench_sim.errors.BenchSimError`) naming the file, the key or row, the value and what is
allowed.

Formats (docs/calibrate.md has examples)
----------------------------------------
* **CSV** (``.csv``): one row per level; required columns ``exposure_s``, a mean (``mean_dn``,
  or ``signal_dn`` dark-subtracted) and a variance (``var_dn2``, or ``signal_var_dn2``
  dark-subtracted, with ``dark_var_dn2``); the irradiation ``photons_per_pixel`` (0 for a dark
  row), or ``relative_irradiance``, or neither (the exposure time is the abscissa; QE unknown);
  dark rows by ``kind = dark`` or 0 photons, or ``dark_mean_dn``/``dark_var_dn2`` per row;
  optional ``wavelength_nm``, ``pixels`` (pixels per image, for absolute weights), ``images``
  (per mean and variance, default 2), ``bits`` (ADC bits) and ``quantization_var_dn2`` (one
  value each); other columns are ignored, ``#`` lines are comments
  (:mod:`bench_sim.metrics.ptc_table`).
* **TOML** (``.toml``): the quantities of an EMVA 1288 data sheet, :data:`RESULT_KEYS`.
* **XML** (``.xml``): ``Results1288.xml()`` of the ``emva1288`` package (sections
  ``sensitivity``, ``dark_current``, ``spatial``; elements with a ``value``).
* **Descriptor** (``.txt``, or a folder holding ``emva1288.txt`` / ``EMVA1288descriptor.txt``):
  ``n bits width height``, ``b exposure_ns photons`` and ``d exposure_ns``, each followed by
  its ``i path`` image lines (two: a temporal pair; more: a spatial stack).
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench_sim.config import read_toml
from bench_sim.errors import BenchSimError
from bench_sim.io import ImageReadError, read_image
from bench_sim.io.input_files import input_file_problem
from bench_sim.metrics.emva1288 import mean_var_from_pair, spatial_nonuniformity
from bench_sim.metrics.frame_series import FrameSeries
from bench_sim.metrics.ptc_table import PtcTable, make_table
from bench_sim.sensor.model import QUANTIZATION_VAR_DN2
from bench_sim.workflows.calibrate_images import MANIFEST, read_frames_file, read_frames_folder

__all__ = [
    "CalibrationInput",
    "REQUIRED_COLUMNS",
    "RESULT_KEYS",
    "read_input",
    "read_table_csv",
    "read_results_toml",
    "read_results_xml",
    "read_descriptor",
]

REQUIRED_COLUMNS = ("exposure_s",)
#: the per-row columns of a table (make_table's keywords)
_SERIES_COLUMNS = (
    "photons_per_pixel",
    "relative_irradiance",
    "mean_dn",
    "var_dn2",
    "signal_dn",
    "signal_var_dn2",
    "dark_mean_dn",
    "dark_var_dn2",
)
_ALL_COLUMNS = (
    "exposure_s",
    *_SERIES_COLUMNS,
    "kind",
    "wavelength_nm",
    "pixels",
    "bits",
    "images",
    "quantization_var_dn2",
)
#: a row's ``kind`` -> whether it is a dark row
_ROW_KINDS = {"dark": True, "flat": False, "light": False, "bright": False}
#: key -> (required, lower bound, upper bound, meaning)
RESULT_KEYS: dict[str, tuple[bool, float, float, str]] = {
    "K_dn_per_e": (True, 0.0, math.inf, "overall system gain [DN/e-]"),
    "dark_noise_e": (True, 0.0, math.inf, "temporal dark noise sigma_d [e-]"),
    "saturation_capacity_e": (True, 1.0, math.inf, "saturation capacity mu_e.sat [e-]"),
    "qe": (False, 0.0, 1.0, "quantum efficiency (0..1) at wavelength_nm"),
    "wavelength_nm": (False, 200.0, 2000.0, "wavelength of the QE [nm]"),
    "dark_current_e_per_s": (False, 0.0, math.inf, "dark current [e-/s]"),
    "dsnu_e": (False, 0.0, math.inf, "DSNU1288 [e-]"),
    "prnu_percent": (False, 0.0, 50.0, "PRNU1288 [%]"),
    "bits": (False, 1.0, 16.0, "ADC bits"),
    "exposure_s": (False, 0.0, math.inf, "exposure time of the dark measurements [s]"),
}
_TEXT_KEYS = ("name", "source", "notes", "sensor")


@dataclass(frozen=True)
class CalibrationInput:
    """What an input file holds: a table to fit, or EMVA results to take as they are.

    ``kind``: ``"table"``, ``"descriptor"``, ``"images"``, ``"results_toml"`` or
    ``"results_xml"``; ``spatial``: DSNU [DN, divide by K] and PRNU from a descriptor's stacks
    (``dsnu_dn``, ``prnu``, and the dark stack's ``exposure_s``); ``frames``: the images of an
    image input (analysed by :func:`bench_sim.metrics.frame_series.analyse_frames`);
    ``quantization_var_dn2``: the rounding's variance in the dark noise (a table's own, else
    ``1/12``); ``text``: text keys of a results TOML (name, source).
    """

    kind: str
    path: Path
    table: PtcTable | None = None
    results: dict[str, float] = field(default_factory=dict)
    spatial: dict[str, float] = field(default_factory=dict)
    text: dict[str, str] = field(default_factory=dict)
    frames: FrameSeries | None = None
    quantization_var_dn2: float = QUANTIZATION_VAR_DN2


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchSimError(f"{path}: cannot read the table ({exc.__class__.__name__})") from exc
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    rows = list(csv.reader(lines))
    if len(rows) < 2:
        raise BenchSimError(f"{path}: no table: expected a header line and one row per level")
    return [h.strip() for h in rows[0]], rows[1:]


def _table_columns(path: Path, header: list[str]) -> None:
    """Refuse a table without its required columns (an exposure, a mean and a variance)."""
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    for raw, sub in (("mean_dn", "signal_dn"), ("var_dn2", "signal_var_dn2")):
        if raw not in header and sub not in header:
            missing.append(f"{raw} (or {sub}, dark-subtracted)")
    if missing:
        raise BenchSimError(
            f"{path}: missing column(s) {', '.join(missing)}; required: exposure_s, mean_dn or signal_dn, "
            "var_dn2 or signal_var_dn2"
        )


def read_table_csv(path: Path) -> CalibrationInput:
    """Read a photon-transfer table (CSV, see the module doc) into a checked :class:`PtcTable`."""
    header, rows = _rows(path)
    _table_columns(path, header)
    for i, r in enumerate(rows):
        if len(r) != len(header):
            raise BenchSimError(f"{path}: row {i + 1} has {len(r)} fields, the header {len(header)}")
    data = {c: [r[header.index(c)].strip() for r in rows] for c in header if c in _ALL_COLUMNS}

    def const(name: str) -> float | None:
        if name not in data:
            return None
        vals = {v for v in data[name] if v}
        if len(vals) != 1:
            raise BenchSimError(
                f"{path}: column {name}: expected one value for the table, got {sorted(vals)}"
            )
        try:
            return float(vals.pop())
        except ValueError as exc:
            raise BenchSimError(f"{path}: column {name}: not a number") from exc

    def num(name: str) -> list[float] | None:
        if name not in data:
            return None
        out = []
        for i, v in enumerate(data[name]):
            try:
                out.append(float(v))
            except ValueError as exc:
                raise BenchSimError(f"{path}: row {i + 1}: {name} = {v!r} is not a number") from exc
        return out

    dark = None
    if "kind" in data:
        kinds = [v.lower() for v in data["kind"]]
        bad = next((i for i, v in enumerate(kinds) if v not in _ROW_KINDS), None)
        if bad is not None:
            raise BenchSimError(f"{path}: row {bad + 1}: kind = {data['kind'][bad]!r}; allowed: dark, flat")
        dark = [_ROW_KINDS[v] for v in kinds]
    consts = {k: const(k) for k in ("pixels", "bits", "images", "wavelength_nm", "quantization_var_dn2")}
    table = make_table(
        num("exposure_s"),
        photons_per_pixel=num("photons_per_pixel"),
        relative_irradiance=num("relative_irradiance"),
        mean_dn=num("mean_dn"),
        var_dn2=num("var_dn2"),
        signal_dn=num("signal_dn"),
        signal_var_dn2=num("signal_var_dn2"),
        dark_mean_dn=num("dark_mean_dn"),
        dark_var_dn2=num("dark_var_dn2"),
        dark=dark,
        pixels=None if consts["pixels"] is None else int(consts["pixels"]),
        bits=None if consts["bits"] is None else int(consts["bits"]),
        images=2 if consts["images"] is None else int(consts["images"]),
        dark_images=2 if consts["images"] is None else int(consts["images"]),
        wavelength_nm=consts["wavelength_nm"],
        source=str(path),
    )
    q = consts["quantization_var_dn2"]
    return CalibrationInput(
        kind="table", path=path, table=table, quantization_var_dn2=QUANTIZATION_VAR_DN2 if q is None else q
    )


def _check_results(path: Path, values: dict[str, float]) -> dict[str, float]:
    for key, (required, lo, hi, meaning) in RESULT_KEYS.items():
        if key not in values:
            if required:
                raise BenchSimError(
                    f"{path}: missing {key} ({meaning}); required: K_dn_per_e, "
                    "dark_noise_e, saturation_capacity_e"
                )
            continue
        v = values[key]
        ok = math.isfinite(v) and (lo < v <= hi if key in ("K_dn_per_e", "qe") else lo <= v <= hi)
        if not ok:
            raise BenchSimError(f"{path}: {key} = {v!r}: {meaning} must lie in {lo:g}..{hi:g}")
    return values


def read_results_toml(path: Path) -> CalibrationInput:
    """Read EMVA 1288 results (TOML: :data:`RESULT_KEYS`, plus ``name``/``source`` text)."""
    raw = read_toml(path, str(path), "EMVA 1288 results")
    values: dict[str, float] = {}
    text: dict[str, str] = {}
    for key, v in raw.items():
        if key in _TEXT_KEYS:
            text[key] = str(v)
        elif key not in RESULT_KEYS:
            allowed = ", ".join([*RESULT_KEYS, *_TEXT_KEYS])
            raise BenchSimError(f"{path}: unknown key {key!r}; allowed: {allowed}")
        elif isinstance(v, bool) or not isinstance(v, int | float):
            raise BenchSimError(f"{path}: {key} = {v!r}: must be a number")
        else:
            values[key] = float(v)
    return CalibrationInput(kind="results_toml", path=path, results=_check_results(path, values), text=text)


#: emva1288 XML (section, element) -> (key, factor)
_XML = {
    ("sensitivity", "K"): ("K_dn_per_e", 1.0),
    ("sensitivity", "QE"): ("qe", 0.01),
    ("sensitivity", "sigma_d"): ("dark_noise_e", 1.0),
    ("sensitivity", "u_e_sat"): ("saturation_capacity_e", 1.0),
    ("dark_current", "u_I_mean"): ("dark_current_e_per_s", 1.0),
    ("spatial", "DSNU1288"): ("dsnu_e", 1.0),
    ("spatial", "PRNU1288"): ("prnu_percent", 1.0),
}


def read_results_xml(path: Path) -> CalibrationInput:
    """Read the results XML the ``emva1288`` package writes (``Results1288.xml(filename)``)."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise BenchSimError(f"{path}: not a readable XML file ({exc})") from exc
    values: dict[str, float] = {}
    for (sec, name), (key, factor) in _XML.items():
        node = root.find(f"{sec}/{name}/value")
        if node is None or node.text is None:
            continue
        try:
            v = float(node.text) * factor
        except ValueError:
            continue
        if math.isfinite(v):  # the package writes nan where a quantity was not measured
            values[key] = v
    return CalibrationInput(kind="results_xml", path=path, results=_check_results(path, values))


def _parse_descriptor(path: Path) -> tuple[int, int, int, list[tuple[str, float, float, list[Path]]]]:
    """``(bits, width, height, [(kind 'b'|'d', exposure_ns, photons, images)])``."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchSimError(f"{path}: cannot read the descriptor ({exc.__class__.__name__})") from exc
    bits = width = height = 0
    levels: list[tuple[str, float, float, list[Path]]] = []
    for no, raw in enumerate(lines, 1):
        tok = raw.split()
        if not tok or tok[0].startswith("#") or tok[0] == "v":
            continue
        try:
            if tok[0] == "n":
                bits, width, height = (int(t) for t in tok[1:4])
            elif tok[0] in ("b", "d"):
                ph = float(tok[2]) if tok[0] == "b" else 0.0
                levels.append((tok[0], float(tok[1]), ph, []))
            elif tok[0] == "i" and levels:
                levels[-1][3].append(path.parent / " ".join(tok[1:]).replace("\\", "/"))
            else:
                raise ValueError(tok[0])
        except (ValueError, IndexError) as exc:
            raise BenchSimError(
                f"{path}: line {no}: {raw.strip()!r} is not a descriptor line (n, b, d, i)"
            ) from exc
    if not bits or not levels:
        raise BenchSimError(
            f"{path}: not an EMVA 1288 descriptor: no 'n bits width height' line or no levels"
        )
    return bits, width, height, levels


def _read(img: Path) -> np.ndarray:
    try:
        return read_image(img)
    except ImageReadError as exc:
        raise BenchSimError(str(exc)) from exc


def read_descriptor(path: Path) -> CalibrationInput:
    """Read an EMVA 1288 descriptor and its images into a table (temporal pairs) and the
    spatial non-uniformity of its stacks (the first bright and dark stacks of more than two
    images)."""
    if path.is_dir():
        found = [path / n for n in ("emva1288.txt", "EMVA1288descriptor.txt") if (path / n).is_file()]
        if not found:
            raise BenchSimError(f"{path}: a folder without emva1288.txt or EMVA1288descriptor.txt")
        path = found[0]
    bits, width, height, levels = _parse_descriptor(path)
    rows: list[tuple[float, float, float, float]] = []
    stacks: dict[str, np.ndarray] = {}
    stack_t: dict[str, float] = {}
    for kind, t_ns, ph, images in levels:
        if len(images) == 2:
            mean, var = mean_var_from_pair(_read(images[0]), _read(images[1]))
            rows.append((t_ns * 1e-9, ph if kind == "b" else 0.0, mean, var))
        elif len(images) > 2 and kind not in stacks:
            stacks[kind] = np.stack([_read(p) for p in images])
            stack_t[kind] = t_ns * 1e-9
    spatial: dict[str, float] = {}
    if "b" in stacks and "d" in stacks:
        sp = spatial_nonuniformity(stacks["b"], stacks["d"], 1.0)
        spatial = {"dsnu_dn": sp["dsnu_e"], "prnu": sp["prnu"], "exposure_s": stack_t["d"]}
    lit = sorted((r for r in rows if r[1] > 0), key=lambda r: r[1])
    arr = np.array([*(r for r in rows if r[1] == 0), *lit], dtype=np.float64).reshape(-1, 4)
    table = make_table(
        arr[:, 0],
        photons_per_pixel=arr[:, 1],
        mean_dn=arr[:, 2],
        var_dn2=arr[:, 3],
        pixels=width * height,
        bits=bits,
        source=str(path),
    )
    return CalibrationInput(kind="descriptor", path=path, table=table, spatial=spatial)


def _images(p: Path) -> CalibrationInput:
    series = read_frames_folder(p) if p.is_dir() else read_frames_file(p)
    return CalibrationInput(kind="images", path=p, frames=series)


def read_input(path: str | Path) -> CalibrationInput:
    """Read any calibration input by its suffix (``.csv``, ``.toml``, ``.xml``, a frames
    ``.npz``, a descriptor ``.txt``, or a folder holding ``frames.csv`` or a descriptor)."""
    p = Path(path)
    if not p.exists():
        raise BenchSimError(f"{p}: no such file or folder")
    problem = input_file_problem(p)  # a FIFO or a device is never opened
    if problem is not None and not p.is_dir():
        raise BenchSimError(f"{p}: {problem}")
    suffix = p.suffix.lower()
    if (p.is_dir() and (p / MANIFEST).is_file()) or suffix == ".npz":
        return _images(p)
    if p.is_dir() or suffix == ".txt":
        return read_descriptor(p)
    readers = {".csv": read_table_csv, ".toml": read_results_toml, ".xml": read_results_xml}
    if suffix not in readers:
        raise BenchSimError(
            f"{p}: unknown input type {suffix or '(no suffix)'!r}; allowed: .csv (photon-transfer table), "
            ".toml or .xml (EMVA 1288 results), .npz or a folder with frames.csv (images), .txt or a "
            "folder (EMVA 1288 descriptor with images)"
        )
    return readers[suffix](p)
