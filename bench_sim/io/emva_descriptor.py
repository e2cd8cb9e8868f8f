"""The EMVA 1288 descriptor file: the list of the images of a photon-transfer measurement in
the format the ``emva1288`` reference package reads."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bench_sim.io.files import write_text
from bench_sim.io.tables import comment_lines

__all__ = ["write_emva_descriptor"]


def write_emva_descriptor(
    path: str | os.PathLike[str],
    *,
    bits: int,
    width: int,
    height: int,
    bright: list[tuple[float, float, list[str]]],
    dark: list[tuple[float, list[str]]],
    title: str = "",
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write an EMVA 1288 descriptor file (the format the ``emva1288`` reference package reads).

    Lines: ``v 4.0``, ``n bits width height``; per bright level ``b exposure_ns photons`` and per
    dark level ``d exposure_ns``, each followed by its ``i path`` lines (2 images: a temporal
    pair; more: a spatial stack). Comment lines (``#``) carry ``title`` and the provenance.

    Parameters
    ----------
    bright
        ``(exposure_ns, photons, image paths)`` per bright level (paths relative to the file).
    dark
        ``(exposure_ns, image paths)`` per dark level.
    """
    lines = ([f"# {title}"] if title else []) + comment_lines(metadata)
    lines += ["v 4.0", f"n {int(bits)} {int(width)} {int(height)}"]
    for exposure_ns, photons, names in bright:
        lines.append(f"b {exposure_ns:.3f} {photons:.9g}")
        lines += [f"i {n}" for n in names]
    for exposure_ns, names in dark:
        lines.append(f"d {exposure_ns:.3f}")
        lines += [f"i {n}" for n in names]
    return write_text(path, "\n".join(lines) + "\n")
