"""The pedestal of stage images from their files: ``fuse``'s default for ``--pedestal``.

bench_sim's own stage images (``simulate --format tiff``, ``reproduce``'s ``gamma1.tiff`` and
``gamma2.tiff``) carry their provenance as JSON (the TIFF ImageDescription, the
EXR header attribute ``bench_sim``, the PNG text chunk ``bench_sim``), whose resolved config
names the digital pedestal the words carry, ``dtdi.pedestal_dn``. A real camera's files carry
none of it: their pedestal is 0 unless the user says otherwise.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from bench_sim.errors import BenchSimError
from bench_sim.io import read_png_text

__all__ = ["file_provenance", "file_pedestal_dn", "default_pedestal_dn"]


def _tiff_description(path: Path) -> str | None:
    import tifffile

    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        with tifffile.TiffFile(path) as tif:
            return tif.pages[0].description if len(tif.pages) else None  # type: ignore[union-attr]
    finally:
        log.setLevel(level)


def _exr_attribute(path: Path) -> str | None:
    import OpenEXR

    with OpenEXR.File(str(path), header_only=True) as f:
        raw = f.header().get("bench_sim")
    return raw.decode() if isinstance(raw, bytes) else raw


def file_provenance(path: str | Path) -> dict[str, Any]:
    """The bench_sim provenance (JSON) an image file carries, ``{}`` if none or unreadable.

    Parameters
    ----------
    path
        A TIFF, EXR, PNG or NPY image (NPY files carry none).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            text = _tiff_description(p)
        elif suffix == ".exr":
            text = _exr_attribute(p)
        elif suffix == ".png":
            return read_png_text(p) or {}
        else:
            return {}
        data = json.loads(text) if text else {}
    except (OSError, ValueError, KeyError, RuntimeError, TypeError):
        return {}  # not ours, or unreadable here: the image reader reports a broken file
    return data if isinstance(data, dict) else {}


def file_pedestal_dn(path: str | Path) -> int | None:
    """``dtdi.pedestal_dn`` [DN] of the bench that made the image file ``path``, ``None`` when
    the file carries no bench_sim config (a real camera's image)."""
    cfg = file_provenance(path).get("config")
    dtdi = cfg.get("dtdi") if isinstance(cfg, dict) else None
    value = dtdi.get("pedestal_dn") if isinstance(dtdi, dict) else None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return int(value)


def default_pedestal_dn(low: str | Path, high: str | Path) -> tuple[float, str]:
    """The pedestal [DN] to subtract from two stage images when ``--pedestal`` is not given,
    and why.

    Returns
    -------
    (float, str)
        The pedestal both files' bench_sim metadata name (``dtdi.pedestal_dn``), or ``0`` when
        neither names one (a plain word, as a real camera writes), with a sentence saying which.

    Raises
    ------
    BenchSimError
        The two files name different pedestals (they come from different benches).
    """
    found = {str(p): file_pedestal_dn(p) for p in (low, high)}
    named = {v for v in found.values() if v is not None}
    if len(named) > 1:
        raise BenchSimError(
            "--pedestal not given and the inputs' metadata disagree: dtdi.pedestal_dn = "
            + ", ".join(f"{v} ({k})" for k, v in found.items())
            + "; give --pedestal"
        )
    if not named:
        return 0.0, (
            "0 DN (the inputs carry no bench_sim metadata: a plain word; give --pedestal N for a "
            "camera whose words carry an offset)"
        )
    value = named.pop()
    which = [k for k, v in found.items() if v is not None]
    source = "both inputs'" if len(which) == 2 else f"{which[0]}'s"
    return float(value), f"{value} DN (dtdi.pedestal_dn from {source} bench_sim metadata)"
