"""An image file's size from its header, refused before any decoder when it is empty or too large.

A decoder trusts the header: a PNG whose header claims 100 000 x 100 000 pixels makes Pillow
raise its decompression-bomb error (or another decoder allocate the pixels) before bench_sim
could say anything. :func:`header_size` reads the width and height alone -- a few bytes by hand
for PNG (``IHDR``), BMP (``BITMAPINFOHEADER`` or ``BITMAPCOREHEADER``) and JPEG (the first
``SOFn`` marker), the header-only readers of tifffile (the first IFD) and OpenEXR
(``header_only``), NumPy's header reader for NPY -- and :func:`image_size_problem` refuses an
empty image and one of more than :data:`MAX_IMAGE_PIXELS` pixels (for the formats Pillow
decodes, also its own decompression-bomb bound) in one line, before the file is decoded.

References
----------
.. [PNG] ISO/IEC 15948:2004, Portable Network Graphics: 5.2 signature, 11.2.2 ``IHDR``.
.. [JPEG] ITU-T T.81 (1992), annex B.1.1.3 markers, B.2.2 frame header (``SOFn``).
.. [BMP] Microsoft, ``BITMAPFILEHEADER``, ``BITMAPINFOHEADER``, ``BITMAPCOREHEADER`` structures.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

__all__ = ["MAX_IMAGE_PIXELS", "header_size", "image_size_problem"]

#: Most pixels (width x height) of an image file read: 2.1 G, 16 GiB as float64 -- a header
#: claiming more is refused before decoding (damaged or hostile); below it, each command's memory
#: check refuses what does not fit this machine.
MAX_IMAGE_PIXELS = 1 << 31
#: Bytes of a JPEG file searched for its frame header (markers before the first ``SOFn``)
_JPEG_SEARCH_BYTES = 1 << 22
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: ``SOFn`` markers: 0xC0..0xCF but DHT (0xC4), JPG (0xC8) and DAC (0xCC)
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: JPEG markers without a length field: TEM, RST0..7, SOI, EOI
_JPEG_BARE = frozenset({0x01, *range(0xD0, 0xDA)})


class _HeaderError(ValueError):
    """A header that cannot be read: the message says what was found."""


def _png(f: BinaryIO) -> tuple[int, int]:
    head = f.read(24)
    if len(head) < 24 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise _HeaderError("not a PNG file (no PNG signature and IHDR chunk)")
    width, height = struct.unpack(">II", head[16:24])
    return height, width


def _bmp(f: BinaryIO) -> tuple[int, int]:
    head = f.read(26)
    if len(head) < 26 or head[:2] != b"BM":
        raise _HeaderError("not a BMP file (no 'BM' header)")
    if struct.unpack("<I", head[14:18])[0] == 12:  # BITMAPCOREHEADER: 16-bit sizes
        width, height = struct.unpack("<HH", head[18:22])
    else:  # BITMAPINFOHEADER and its successors; a negative height: rows top-down
        width, height = struct.unpack("<ii", head[18:26])
    return abs(height), abs(width)


def _jpeg(f: BinaryIO) -> tuple[int, int]:
    data = f.read(_JPEG_SEARCH_BYTES)
    if data[:2] != b"\xff\xd8":
        raise _HeaderError("not a JPEG file (no SOI marker)")
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            raise _HeaderError(f"not a JPEG file (no marker at byte {i})")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _JPEG_BARE:
            i += 2
            continue
        length = struct.unpack(">H", data[i + 2 : i + 4])[0]
        if marker in _JPEG_SOF:
            if i + 9 > len(data):
                break
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            return height, width
        i += 2 + length
    raise _HeaderError("no JPEG frame header (SOFn) found")


def _tiff(path: Path) -> tuple[int, int]:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        page = tif.pages.first
        return int(page.imagelength), int(page.imagewidth)


def _exr(path: Path) -> tuple[int, int]:
    import OpenEXR

    with OpenEXR.File(str(path), header_only=True) as f:
        (x0, y0), (x1, y1) = f.header()["dataWindow"]
    return int(y1 - y0 + 1), int(x1 - x0 + 1)


def _npy(path: Path) -> tuple[int, int]:
    with open(path, "rb") as f:
        version = np.lib.format.read_magic(f)
        fmt = np.lib.format
        read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, _ = read(f)
    shape = tuple(int(n) for n in shape)
    if len(shape) < 2:
        return (shape[0] if shape else 1), 1
    return shape[0], int(np.prod(shape[1:]))


_BY_HAND = {".png": _png, ".bmp": _bmp, ".jpg": _jpeg, ".jpeg": _jpeg}
_BY_LIBRARY = {".tif": _tiff, ".tiff": _tiff, ".exr": _exr, ".npy": _npy}
#: the formats Pillow decodes (its decompression-bomb bound applies too)
_PILLOW = frozenset(_BY_HAND)


def header_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """``(height, width)`` [pixels] of an image file as its header states it, without decoding
    the pixels (NPY: the first axis and the product of the others); ``None`` for a suffix not
    known here. Raises ``ValueError`` naming what was found for a header that cannot be read."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in _BY_HAND:
        with open(p, "rb") as f:
            return _BY_HAND[suffix](f)
    if suffix in _BY_LIBRARY:
        return _BY_LIBRARY[suffix](p)
    return None


def _pillow_bound() -> int:
    """Pillow's decompression-bomb bound [pixels]: it refuses more than twice its
    ``MAX_IMAGE_PIXELS`` when it opens a file."""
    from PIL import Image

    limit = Image.MAX_IMAGE_PIXELS
    return MAX_IMAGE_PIXELS if limit is None else min(MAX_IMAGE_PIXELS, 2 * int(limit))


def image_size_problem(path: str | os.PathLike[str], max_pixels: int | None = None) -> str | None:
    """Why the image file ``path`` is not read, from its header alone: ``"empty image (0 x 5
    pixels)"``, ``"its header claims 100000 x 100000 = 10000000000 pixels: more than 2147483648
    (a damaged or hostile file?)"``, ``"cannot read its header (...)"``; ``None`` when its size
    is fine or its suffix is not known here. ``max_pixels`` defaults to :data:`MAX_IMAGE_PIXELS`
    (and, for PNG, BMP and JPEG, Pillow's bound)."""
    suffix = Path(path).suffix.lower()
    try:
        size = header_size(path)
    except Exception as exc:  # the header readers raise many kinds for a broken file
        detail = " ".join(str(exc).split())[:160] or type(exc).__name__
        return f"cannot read its header ({detail})"
    if size is None:
        return None
    height, width = size
    if height == 0 or width == 0:
        return f"empty image ({width} x {height} pixels)"
    bound = max_pixels if max_pixels is not None else (
        _pillow_bound() if suffix in _PILLOW else MAX_IMAGE_PIXELS)
    if width * height > bound:
        return (
            f"its header claims {width} x {height} = {width * height} pixels: more than {bound} "
            "(a damaged or hostile file?)"
        )
    return None
