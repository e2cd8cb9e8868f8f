"""File-name patterns whose walk is bounded: a pattern over the whole file system is refused in
one line within about a second, not walked for minutes without a word.

``glob.glob("/**/*.png", recursive=True)`` lists every folder of the machine before it returns.
:func:`bounded_glob` first counts the folders the pattern makes ``glob`` list -- every folder
below the pattern's fixed part (the leading components without wildcards) down to the depth its
wildcard components reach, all of them below a ``**`` -- and refuses the pattern once more than
:data:`MAX_GLOB_FOLDERS` would be listed; only then does it glob.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path

from bench_sim.errors import BenchSimError

__all__ = ["MAX_GLOB_FOLDERS", "bounded_glob", "glob_folders"]

#: Most folders a pattern may make ``glob`` list (a dataset's images lie in a few)
MAX_GLOB_FOLDERS = 10_000


def _split(pattern: str) -> tuple[Path, list[str]]:
    """The pattern's fixed leading folder and its remaining components (the first with a
    wildcard on)."""
    parts = Path(pattern).parts
    for i, part in enumerate(parts):
        if glob.has_magic(part):
            return Path(*parts[:i]) if i else Path("."), list(parts[i:])
    return Path(pattern).parent, [Path(pattern).name]


def glob_folders(pattern: str, limit: int = MAX_GLOB_FOLDERS) -> tuple[int, Path]:
    """The number of folders ``glob`` would list for ``pattern`` (counted up to ``limit + 1``,
    then stopped) and the fixed folder the walk starts from."""
    root, rest = _split(pattern)
    depth = None if "**" in rest else len(rest) - 1  # levels of folders below root to list
    count = 0
    level = [root]
    d = 0
    while level and count <= limit:
        below: list[Path] = []
        for folder in level:
            count += 1
            if count > limit or (depth is not None and d >= depth):
                continue
            try:
                with os.scandir(folder) as it:
                    below += [Path(e.path) for e in it if e.is_dir()]
            except OSError:  # unreadable or gone: glob skips it too
                continue
        level, d = below, d + 1
    return count, root


def bounded_glob(pattern: str, what: str, limit: int = MAX_GLOB_FOLDERS) -> list[str]:
    """``glob.glob(pattern, recursive=True)`` once the walk is known to list at most ``limit``
    folders; :class:`~bench_sim.errors.BenchSimError` (``what: ...``, one line) otherwise."""
    count, root = glob_folders(pattern, limit)
    if count > limit:
        raise BenchSimError(
            f"{what}: the pattern walks more than {limit} folders below {root} (a pattern over the "
            "whole file system?); give a narrower pattern, e.g. the folder that holds the images"
        )
    return glob.glob(pattern, recursive=True)
