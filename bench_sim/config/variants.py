"""Names a bench may give ``render.variant`` (or ``BENCH_SIM_VARIANT``): ``"auto"``, a backend
kind, or a Mitsuba variant of the installed Mitsuba for the colour mode.

The one list of allowed names and its check (:func:`check_variant_name`), used by the config
(``render.variant``) and by :mod:`bench_sim.runtime.backend` (the environment variable). The
installed variants are read from Mitsuba's ``config.py`` without importing Mitsuba.
"""

from __future__ import annotations

import ast
from importlib.metadata import PackageNotFoundError, files
from pathlib import Path

from bench_sim.errors import BenchSimError

__all__ = ["KINDS", "mitsuba_variants", "allowed_variants", "check_variant_name"]

#: Backend kinds a preference may name instead of a variant.
KINDS = ("cuda", "llvm", "scalar")


def mitsuba_variants() -> tuple[str, ...]:
    """The variants the installed Mitsuba was built with, read from its ``config.py`` without
    importing Mitsuba (``()`` if Mitsuba is not installed)."""
    try:  # the installed files (an imported Mitsuba replaces its own module spec)
        paths = [Path(str(f.locate())) for f in files("mitsuba") or () if f.name == "config.py"]
    except PackageNotFoundError:
        return ()
    for path in paths:
        if path.parent.name != "mitsuba":
            continue
        try:
            tree = ast.parse(path.read_text())
        except (OSError, SyntaxError, ValueError):
            continue
        for node in tree.body:
            if (
                isinstance(node, ast.Assign)
                and any(isinstance(t, ast.Name) and t.id == "MI_VARIANTS" for t in node.targets)
            ):
                value = ast.literal_eval(node.value)
                return tuple(str(v) for v in value)
    return ()


def allowed_variants(mode: str) -> list[str]:
    """Installed Mitsuba variants usable for colour ``mode``: ``*_mono`` / ``*_rgb`` for mono,
    ``*_spectral`` for spectral rendering (polarised variants are not used)."""
    want = "spectral" if mode == "spectral" else ("mono", "rgb")
    return [
        v for v in mitsuba_variants() if "polarized" not in v and v.rsplit("_", 1)[-1] in want
    ]


def check_variant_name(prefer: str, mode: str = "mono", source: str = "render.variant") -> None:
    """Refuse a preference that names no backend kind and no usable Mitsuba variant.

    Allowed: ``"auto"``, ``"cuda"``, ``"llvm"``, ``"scalar"``, or a variant the installed Mitsuba
    has for the colour mode (``*_mono`` / ``*_rgb`` for mono, ``*_spectral`` for spectral
    rendering; polarised variants are not used). Raises :class:`BenchSimError` naming ``source``.
    """
    if prefer in ("auto", *KINDS):
        return
    allowed = allowed_variants(mode)
    if prefer in allowed:
        return
    known = mitsuba_variants()
    why = (
        f"not a variant for {mode} rendering" if prefer in known
        else "not a Mitsuba variant of this installation" if known
        else "Mitsuba is not installed"
    )
    listed = ", ".join(allowed) if allowed else "-"
    raise BenchSimError(
        f"{source} = {prefer!r}: {why}; allowed 'auto', 'cuda', 'llvm', 'scalar' or one of: {listed}"
    )
