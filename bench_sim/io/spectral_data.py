"""Measured spectra by name, from the colour-science package, or from a user's CSV file.

Three kinds (:data:`SPECTRUM_KINDS`), each a table of (wavelength [nm], value) with its source:

``light``
    Emission spectra: the CIE and ISO illuminants of ``colour.SDS_ILLUMINANTS`` (``A``: the
    tungsten halogen / incandescent lamp at 2856 K; ``FL1`` .. ``FL12`` and ``FL3.1`` ..
    ``FL3.15``: fluorescent lamps; ``LED-B1`` .. ``LED-B5``, ``LED-BH1``, ``LED-RGB1``,
    ``LED-V1``, ``LED-V2``: white LEDs; ``HP1`` .. ``HP5``: high-pressure discharge lamps;
    ``D50``, ``D65``, ...: daylight) and the measured lamps of ``colour.SDS_LIGHT_SOURCES``
    (``Incandescent``, ``Kinoton 75P``, ``Philips TL-84``, ``Luxeon WW 2880``, ...).
``reflectance``
    Reflectance spectra 0..1: the patches of the charts of ``colour.SDS_COLOURCHECKERS``, named
    ``CHART/PATCH`` (``ColorChecker N Ohta/dark skin``, ``BabelColor Average/neutral 5 (.70 D)``,
    ``ISO 17321-1/...``).
``qe``
    Spectral responses of cameras, ``colour.MSDS_CAMERA_SENSITIVITIES``, one channel each:
    ``CAMERA/CHANNEL`` (``Nikon 5100 (NPL)/green``); colour-science has no monochrome sensor's
    QE, whose curve comes as a CSV.

``csv:PATH`` names a CSV file instead (:func:`read_spectrum_csv`): a header, then rows of a
wavelength (a column ``wavelength_nm``, or ``wavelength_m``) and one value column, ``#`` lines
skipped. Every spectrum carries its source (the package, its version and the table; or the file
and its SHA-256) for the provenance. A name that is none of these is one line with the names
closest to it (``did you mean``). colour-science is imported only when a name is looked up.

The data are colour-science's (BSD-3-Clause), which cites the original measurements
(CIE 15:2004 and CIE 15:2018 for the illuminants; N. Ohta, BabelColor and ISO 17321-1 for the
ColorChecker; the National Physical Laboratory for the camera responses); bench_sim ships none.
"""

from __future__ import annotations

import difflib
import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io.tables import read_csv_columns

__all__ = ["SPECTRUM_KINDS", "CSV_PREFIX", "Spectrum", "spectrum_names", "named_spectrum",
           "read_spectrum_csv", "load_spectrum", "spectrum_name_problem"]

#: the kinds of spectra and the colour-science tables each is looked up in
SPECTRUM_KINDS = {
    "light": ("SDS_ILLUMINANTS", "SDS_LIGHT_SOURCES"),
    "reflectance": ("SDS_COLOURCHECKERS",),
    "qe": ("MSDS_CAMERA_SENSITIVITIES",),
}
#: prefix of a spectrum named by a CSV file
CSV_PREFIX = "csv:"
#: words a user may put before a name (``CIE A``) that colour-science's names do not have
_PREFIXES = ("cie illuminant ", "cie ", "illuminant ")


@dataclass(frozen=True)
class Spectrum:
    """A tabulated spectrum: ``wavelength_nm`` (increasing), ``values`` and its ``source``."""

    wavelength_nm: np.ndarray
    values: np.ndarray
    source: str

    def at(self, wl_nm: np.ndarray) -> np.ndarray:
        """The values at ``wl_nm`` [nm], linear between the table's points (the caller checks
        that ``wl_nm`` lies inside them: :meth:`covers`)."""
        return np.interp(np.asarray(wl_nm, dtype=np.float64), self.wavelength_nm, self.values)

    def covers(self, lo_nm: float, hi_nm: float) -> bool:
        """Whether the table reaches from ``lo_nm`` to ``hi_nm``."""
        return bool(self.wavelength_nm[0] <= lo_nm + 1e-9 and self.wavelength_nm[-1] >= hi_nm - 1e-9)


def _colour() -> Any:
    """colour-science, imported here (about 1.5 s, only when a name is looked up) with numpy's
    print options kept: its import sets them to numpy 1.13's (``str`` of a float64 to 12 digits),
    which would change how every other library in the process writes numbers."""
    options = np.get_printoptions()
    try:
        import colour
    finally:
        np.set_printoptions(**options)
    return colour


def _entries(kind: str) -> dict[str, Any]:
    """``{name: spectral distribution}`` of one kind, each table's aliases left out (the same
    object under another key)."""
    colour = _colour()
    out: dict[str, Any] = {}
    for table_name in SPECTRUM_KINDS[kind]:
        table = getattr(colour, table_name)
        seen: set[int] = set()
        for key in table.keys():  # noqa: SIM118 - colour's mappings list their own keys
            value = table[key]
            if id(value) in seen:
                continue
            seen.add(id(value))
            if kind == "light":
                out[str(key)] = (value, f"colour.{table_name}[{key!r}]")
            elif kind == "reflectance":
                for patch in value.keys():  # noqa: SIM118
                    out[f"{key}/{patch}"] = (value[patch], f"colour.{table_name}[{key!r}][{patch!r}]")
            else:
                for k, channel in enumerate(value.labels):
                    where = f"colour.{table_name}[{key!r}], channel {channel!r}"
                    out[f"{key}/{channel}"] = ((value, k), where)
    return out


@functools.cache
def spectrum_names(kind: str) -> tuple[str, ...]:
    """Every name of one kind (module docstring), in colour-science's order."""
    if kind not in SPECTRUM_KINDS:
        raise ValueError(f"spectrum kind {kind!r}: one of {', '.join(SPECTRUM_KINDS)}")
    return tuple(_entries(kind))


def spectrum_name_problem(kind: str, name: str) -> str | None:
    """Why ``name`` is not a spectrum of ``kind`` (one line), with the closest names; ``None`` if
    it is one (or a ``csv:`` file: checked when read)."""
    if name.startswith(CSV_PREFIX):
        return None if name[len(CSV_PREFIX):].strip() else "csv: needs a file name"
    names = spectrum_names(kind)
    if name in names:
        return None
    folded = {n.casefold(): n for n in names}
    low = name.casefold()
    tries = [low] + [low.removeprefix(p) for p in _PREFIXES if low.startswith(p)]
    close = list(dict.fromkeys(c for t in tries for c in difflib.get_close_matches(t, list(folded), n=3,
                                                                                   cutoff=0.6)))
    hint = f"; did you mean {', '.join(repr(folded[c]) for c in close[:3])}?" if close else ""
    return (f"not a {kind} spectrum of colour-science ({len(names)} names: bench-sim config keys "
            f"lists them) nor csv:FILE{hint}")


@functools.lru_cache(maxsize=64)
def named_spectrum(kind: str, name: str) -> Spectrum:
    """The spectrum called ``name`` (module docstring); one-line :class:`BenchSimError` with the
    closest names for any other."""
    problem = spectrum_name_problem(kind, name)
    if problem is not None or name.startswith(CSV_PREFIX):
        raise BenchSimError(f"spectrum = {name!r}: {problem or 'a file, not a name (load_spectrum)'}")
    entry, where = _entries(kind)[name]
    if isinstance(entry, tuple):
        msds, k = entry
        wl, values = np.asarray(msds.wavelengths, dtype=np.float64), np.asarray(msds.values)[:, k]
    else:
        wl, values = np.asarray(entry.wavelengths, dtype=np.float64), np.asarray(entry.values)
    source = f"{where}, colour-science {_colour().__version__}"
    return Spectrum(wl, np.asarray(values, dtype=np.float64), source)


def read_spectrum_csv(path: str | Path, label: str) -> Spectrum:
    """A spectrum from a CSV file (module docstring); ``label`` names it in errors."""
    cols = read_csv_columns(path, label)
    if "wavelength_nm" in cols:
        wl = cols.pop("wavelength_nm")
    elif "wavelength_m" in cols:
        wl = cols.pop("wavelength_m") * 1e9
    else:
        raise BenchSimError(f"{label}: needs a column wavelength_nm or wavelength_m (it has "
                            f"{', '.join(cols)})")
    if len(cols) != 1:
        raise BenchSimError(f"{label}: needs one value column beside the wavelength (it has "
                            f"{', '.join(cols)})")
    values = next(iter(cols.values()))
    if np.any(np.diff(wl) <= 0):
        raise BenchSimError(f"{label}: the wavelengths must increase")
    if values.min() < 0:
        raise BenchSimError(f"{label}: negative values ({values.min():g})")
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return Spectrum(wl, values, f"{path} (sha256 {digest})")


def load_spectrum(kind: str, name: str, key: str) -> Spectrum:
    """A spectrum by name or ``csv:FILE`` (``key``: the config key, for errors)."""
    if name.startswith(CSV_PREFIX):
        return read_spectrum_csv(name[len(CSV_PREFIX):].strip(), f"{key} = {name!r}")
    problem = spectrum_name_problem(kind, name)
    if problem is not None:
        raise BenchSimError(f"{key} = {name!r}: {problem}")
    return named_spectrum(kind, name)
