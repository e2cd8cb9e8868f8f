"""What an input path is, named in one line before it is opened.

A path given as an input file can be missing, a folder, a broken link, or a special file: a
character or block device (``/dev/zero``, endless), a FIFO (a named pipe: opening it waits for a
writer, for ever) or a socket. :func:`input_file_problem` tells them apart with one ``stat``,
without opening anything, so each is refused as what it is rather than as "no such file" (or a
read that never ends).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["input_file_problem"]

#: What each kind of special file is called in the message
_SPECIAL = (
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def input_file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` is not a regular file that can be read (``"no such file"``, ``"is a
    folder, not a file"``, ``"is a broken link"``, ``"is a special file (a FIFO (named pipe)),
    not a regular file"``), or ``None``. Links are followed; nothing is opened."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        return "is a broken link" if p.is_symlink() else "no such file"
    except NotADirectoryError:
        return "no such file (a part of the path is a file, not a folder)"
    except OSError as exc:
        return f"cannot be looked at ({exc.strerror or exc})"
    if stat.S_ISDIR(mode):
        return "is a folder, not a file"
    for test, what in _SPECIAL:
        if test(mode):
            return f"is a special file ({what}), not a regular file"
    return None
