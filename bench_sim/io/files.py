"""JSON and text files, written atomically; SHA-256 digests; byte counts for messages.

JSON files carry their provenance as keys (the dict of
:func:`bench_sim.runtime.provenance.provenance`: ``version``, ``seed``, ``config_sha256``,
``config``); they are strict JSON (:func:`bench_sim.io.strict_json.strict_dumps`, the one
encoding of every writer that stores JSON: files, EXR/TIFF/PNG attributes, CSV comment lines).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bench_sim.io.atomic import atomic_path
from bench_sim.io.strict_json import strict_dumps

__all__ = [
    "format_bytes",
    "read_json",
    "sha256_file",
    "sha256_text",
    "write_json",
    "write_text",
]


def format_bytes(n: float) -> str:
    """``n`` bytes for a message: ``'512 B'``, ``'3.4 MiB'``, ``'2.1 TiB'`` (binary prefixes)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover - unreachable


def sha256_text(text: str) -> str:
    """SHA-256 hex digest of a UTF-8 string."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes, read in blocks (input files' provenance)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def write_json(path: str | os.PathLike[str], data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented, key-sorted strict JSON (a non-finite number as ``null``,
    :func:`~bench_sim.io.strict_json.strict_dumps`), atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(strict_dumps(data, indent=2, sort_keys=True) + "\n")
    return path


def read_json(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a JSON file."""
    return json.loads(Path(path).read_text())


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write a text file atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
