"""Image files: OpenEXR, 16-bit TIFF, PNG (arrays and matplotlib figures) and NPY; BMP and JPEG
are read.

Every image written carries its provenance as a JSON attribute: the EXR header attribute
``bench_sim``, the TIFF ImageDescription, the PNG ``tEXt`` chunk ``bench_sim``.

Reading: :func:`check_image_file` is the one check of an input image file (it exists, has a
supported suffix, can be read); :func:`read_image_data` the one reader (the pixels as stored
and, for EXR, the channel names), used by :func:`read_image` (one channel as float64: the stage
images of ``bench-sim fuse``), by :func:`read_image_channel` (one channel of a grey or colour
image, or its ISO 12233 luminance: ``bench-sim mtf``) and by the target images of
:mod:`bench_sim.rig.target_sources`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.io.atomic import atomic_path
from bench_sim.io.image_header import image_size_problem
from bench_sim.io.input_files import input_file_problem
from bench_sim.io.strict_json import strict_dumps

__all__ = [
    "IMAGE_SUFFIXES",
    "IMAGE_CHANNELS",
    "ISO12233_LUMA",
    "ImageReadError",
    "PNG_COMPRESS_LEVEL",
    "check_image_file",
    "image_file_problem",
    "image_shape",
    "read_exr",
    "read_image",
    "read_image_channel",
    "read_image_data",
    "ChannelImage",
    "srgb_to_linear",
    "read_png_text",
    "write_exr",
    "write_figure_png",
    "write_png",
    "write_tiff16",
]

#: suffixes (lower case) of the image files read
IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".exr", ".npy", ".bmp", ".jpg", ".jpeg")
#: the channels :func:`read_image_channel` takes: one of R, G, B, or Y, the luminance
IMAGE_CHANNELS = ("R", "G", "B", "Y")
#: luminance weights of R, G, B for the e-SFR of a colour image (ISO 12233:2014 and :2017, 6.2:
#: ``Y = 0.2125 R + 0.7154 G + 0.0721 B``)
ISO12233_LUMA = (0.2125, 0.7154, 0.0721)


class ImageReadError(BenchSimError):
    """An input image file that cannot be read or is not of a supported kind."""


def write_exr(
    path: str | os.PathLike[str],
    channels: Mapping[str, np.ndarray],
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write 2-D float32 channels of equal shape to one OpenEXR file (ZIP compression).

    Parameters
    ----------
    path
        Destination ``.exr`` file.
    channels
        Channel name to 2-D array (height, width); stored as 32-bit float.
    metadata
        Stored as the header attribute ``bench_sim`` (a JSON string): config, seed, version, units.
    """
    import OpenEXR

    path = Path(path)
    shapes = {np.asarray(a).shape for a in channels.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"EXR channels must be 2-D arrays of one shape, got {sorted(shapes)}")
    header: dict[str, Any] = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if metadata is not None:
        header["bench_sim"] = strict_dumps(metadata, sort_keys=True)
    chans = {
        name: np.ascontiguousarray(np.asarray(arr, dtype=np.float32))
        for name, arr in channels.items()
    }
    with atomic_path(path) as tmp, OpenEXR.File(header, chans) as f:
        f.write(str(tmp))
    return path


def read_exr(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read an OpenEXR file: (channel name -> 2-D float array, bench_sim metadata or {})."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            # copy out while the file is open: the header does not outlive it
            meta_raw = f.header().get("bench_sim")
            meta_text = str(meta_raw) if isinstance(meta_raw, str) else None
            channels = {name: np.array(ch.pixels, copy=True) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises plain Exceptions with varying texts
        raise ImageReadError(f"{path}: not a readable OpenEXR file ({exc})") from exc
    meta = json.loads(meta_text) if meta_text else {}
    return channels, meta


def write_tiff16(
    path: str | os.PathLike[str], image_dn: np.ndarray, metadata: Mapping[str, Any] | None = None
) -> Path:
    """Write a 2-D array of non-negative integers below 65536 as a 16-bit grayscale TIFF.

    The metadata goes into the TIFF ImageDescription tag as JSON.
    """
    import tifffile

    arr = np.asarray(image_dn)
    if arr.ndim != 2:
        raise ValueError(f"{path}: a 16-bit TIFF needs a 2-D image, got shape {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() > 65535):
        raise ValueError(f"{path}: values must lie in 0..65535, got {arr.min()}..{arr.max()}")
    desc = strict_dumps(metadata or {}, sort_keys=True)
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, arr.astype(np.uint16), description=desc, metadata=None)
    return Path(path)


def _png_info(metadata: Mapping[str, Any] | None) -> Any:
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    if metadata is not None:
        info.add_text("bench_sim", strict_dumps(metadata, sort_keys=True))
    return info


#: zlib level of the PNGs written: on the reproduction's figures level 3 encodes in half the time
#: of Pillow's default 6 and gives files no larger (729 vs 834 kB for Fig. 3)
PNG_COMPRESS_LEVEL = 3


def write_png(
    path: str | os.PathLike[str], image: np.ndarray, metadata: Mapping[str, Any] | None = None
) -> Path:
    """Write an 8- or 16-bit grayscale (2-D) or 8-bit RGB (H, W, 3) PNG (Pillow); ``metadata``
    as JSON in the ``tEXt`` chunk ``bench_sim`` (Pillow's ``PngInfo``)."""
    from PIL import Image

    arr = np.asarray(image)
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: PNG needs uint8 or uint16 data, got {arr.dtype}")
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3 and arr.dtype == np.uint8)):
        raise ValueError(f"{path}: PNG needs a 2-D image or 8-bit (H, W, 3) RGB, got {arr.shape} {arr.dtype}")
    img = Image.fromarray(np.ascontiguousarray(arr))
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG", pnginfo=_png_info(metadata), compress_level=PNG_COMPRESS_LEVEL)
    return Path(path)


def write_figure_png(
    path: str | os.PathLike[str], fig: Any, metadata: Mapping[str, Any] | None = None, dpi: float = 110
) -> Path:
    """Render a matplotlib figure to PNG with the ``bench_sim`` text chunk (Pillow ``PngInfo``)
    and close it."""
    import io as _io

    import matplotlib.pyplot as plt

    buf = _io.BytesIO()  # encoded once, with the text chunk (Pillow's PngInfo through matplotlib)
    fig.savefig(buf, format="png", dpi=dpi,
                pil_kwargs={"pnginfo": _png_info(metadata), "compress_level": PNG_COMPRESS_LEVEL})
    plt.close(fig)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.getvalue())
    return Path(path)


def read_png_text(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``bench_sim`` metadata of a PNG written by :func:`write_png` (``{}`` if none)."""
    from PIL import Image

    with Image.open(path) as img:
        text = getattr(img, "text", {}).get("bench_sim")
    return json.loads(text) if text else {}


def carries_provenance(path: str | os.PathLike[str]) -> bool:
    """Whether the image ``path`` carries bench_sim's provenance (an EXR, TIFF or PNG that
    bench_sim wrote: its ``bench_sim`` attribute, description or text chunk with a ``version``);
    ``False`` for anything else, unreadable files included."""
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".exr":
            meta = read_exr(path)[1]
        elif suffix == ".png":
            meta = read_png_text(path)
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                meta = json.loads(getattr(tif.pages.first, "description", "") or "{}")
        else:
            return False
    except Exception:  # a foreign or damaged file: not ours
        return False
    return isinstance(meta, dict) and "version" in meta


def image_file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` cannot be read as an image (``"no such file"``, a folder or special file,
    ``"unsupported file type ..."``, ``"not readable"``, an empty image or one too large by its
    header, :mod:`bench_sim.io.image_header`), or ``None``: the one check of an input image
    file, before anything is decoded. Callers put their own name of the file in front."""
    path = Path(path)
    if (kind := input_file_problem(path)) is not None:  # missing, a folder, a FIFO, a device
        return kind
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        return f"unsupported file type '{suffix}' (allowed: {', '.join(IMAGE_SUFFIXES)})"
    if not os.access(path, os.R_OK):
        return "not readable"
    return image_size_problem(path)  # empty, or too large a size in its header


def check_image_file(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """An existing, readable image file and its lower-case suffix, or :class:`ImageReadError`
    (one line naming the file; see :func:`image_file_problem`)."""
    path = Path(path)
    problem = image_file_problem(path)
    if problem is not None:
        raise ImageReadError(f"{path}: {problem}")
    return path, path.suffix.lower()


def read_image_data(path: str | os.PathLike[str]) -> tuple[np.ndarray, list[str] | None]:
    """The pixels of an image file as stored and, for EXR, the channel names.

    Returns ``(array, names)``: the array (H, W) or (H, W, C) (TIFF may be planar, (C, H, W)) in
    the file's own type; for EXR the channels are stacked along the last axis in name order and
    ``names`` lists them, otherwise ``names`` is ``None``. Suffixes as :data:`IMAGE_SUFFIXES`
    (check the file first with :func:`image_file_problem`); the readers' own exceptions pass
    through (each caller words its one-line error).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        return np.load(path, allow_pickle=False), None
    if suffix == ".exr":
        channels, _ = read_exr(path)
        names = sorted(channels)
        return np.stack([channels[n] for n in names], axis=-1), names
    if suffix in (".tif", ".tiff"):
        import tifffile

        return tifffile.imread(path), None
    if suffix == ".png" and _png_is_16bit_colour(path):
        return _read_png16_colour(path), None
    import imageio.v3 as iio

    return iio.imread(path, plugin="pillow"), None


def _png_is_16bit_colour(path: Path) -> bool:
    """Whether a PNG holds 16-bit RGB or RGBA (its IHDR chunk: bit depth 16, colour type 2 or
    6), which Pillow reads as 8-bit."""
    with open(path, "rb") as fh:
        head = fh.read(26)
    return len(head) == 26 and head[24] == 16 and head[25] in (2, 6)


def _read_png16_colour(path: Path) -> np.ndarray:
    """A 16-bit RGB(A) PNG as (H, W, 3 or 4) uint16 in R, G, B(, A) order (OpenCV reads all 16
    bits; it gives B, G, R(, A))."""
    import cv2

    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if arr is None or arr.ndim != 3:
        raise ValueError("OpenCV could not decode the 16-bit colour PNG")
    order = [2, 1, 0, 3][: arr.shape[2]]
    return np.ascontiguousarray(arr[..., order])


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a single-channel image as a float64 2-D array.

    Supported: 8/16-bit grayscale TIFF and PNG, single-channel (or first-channel) EXR (the
    channel ``Y``, ``R`` or ``gray``, else the first by name), and NPY. Raises
    :class:`ImageReadError` with the file name for anything else.
    """
    path, _ = check_image_file(path)
    try:
        arr, names = read_image_data(path)
        if names is not None:
            name = next((n for n in ("Y", "R", "gray") if n in names), names[0])
            arr = arr[..., names.index(name)]
    except Exception as exc:
        raise ImageReadError(f"{path}: cannot read image ({exc})") from exc
    arr = np.asarray(arr)
    if arr.ndim != 2:
        raise ImageReadError(f"{path}: expected a single-channel 2-D image, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ImageReadError(f"{path}: unsupported pixel type {arr.dtype}")
    return arr.astype(np.float64)


def _channel_names(arr: np.ndarray, names: list[str] | None) -> tuple[np.ndarray, list[str]]:
    """``(H, W, C)`` pixels and their channel names: an EXR's own, R, G, B(, A) for 3 or 4
    channels, else ``0``, ``1``, ...; a planar TIFF (C, H, W) is turned to (H, W, C)."""
    if arr.ndim == 3 and names is None and arr.shape[0] in (3, 4) and arr.shape[-1] not in (3, 4):
        arr = np.moveaxis(arr, 0, -1)
    n = arr.shape[-1]
    if names is None:
        names = ["R", "G", "B", "A"][:n] if n in (3, 4) else [str(i) for i in range(n)]
    return arr, names


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB transfer function inverted (IEC 61966-2-1): encoded 0..1 -> linear 0..1."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


@dataclass(frozen=True)
class ChannelImage:
    """One channel of an image file (:func:`read_image_channel`).

    Attributes
    ----------
    values
        (H, W) float64: the file's values of the channel (linear encoding), or, decoded from sRGB,
        linear 0..1 (integers divided by their type's largest value first).
    raw_top
        (H, W) float64: the largest stored value over the channels that make ``values`` (one, or
        R, G, B for the luminance ``Y``), in the file's units: where a pixel clips.
    integer_top
        The largest value of the file's integer type (255, 65535, ...), ``None`` for floats.
    channel
        The channel read (``None``: a grey image), ``encoding`` how it was decoded.
    """

    values: np.ndarray
    raw_top: np.ndarray
    integer_top: int | None
    channel: str | None
    encoding: str


def _select(
    arr: np.ndarray, names: list[str] | None, channel: str | None, path: Path
) -> tuple[np.ndarray, bool]:
    """The stored planes behind ``channel``: (H, W) or, for the luminance ``Y``, (H, W, 3) R, G,
    B; and whether they are R, G, B to be weighted."""
    if arr.ndim == 3 and arr.shape[-1] == 1 and names is None:
        arr = arr[..., 0]
    if arr.ndim == 2:
        return arr, False
    if arr.ndim != 3:
        raise ImageReadError(f"{path}: shape {arr.shape} is not an image (H, W) or (H, W, channels)")
    arr, names = _channel_names(arr, names)
    if len(names) == 1:
        return arr[..., 0], False
    if channel is None:
        raise ImageReadError(f"{path}: a colour image (channels {', '.join(names)}): choose one with "
                             "--channel R, G, B or Y (luminance)")
    if channel in names:
        return arr[..., names.index(channel)], False
    if channel == "Y" and all(c in names for c in "RGB"):
        return arr[..., [names.index(c) for c in "RGB"]], True
    raise ImageReadError(f"{path}: no channel {channel!r} (the file has {', '.join(names)})")


def read_image_channel(
    path: str | os.PathLike[str], channel: str | None = None, encoding: str = "linear"
) -> ChannelImage:
    """One channel of an image file (:class:`ChannelImage`).

    ``channel``: ``None`` for a single-channel (grey) image; for a colour image ``"R"``, ``"G"``,
    ``"B"`` or ``"Y"``, the luminance ``0.2125 R + 0.7154 G + 0.0721 B`` (:data:`ISO12233_LUMA`;
    of the decoded R, G, B; an EXR's own ``Y`` channel where it has one). A grey image has one
    channel, which every ``channel`` names. ``encoding``: ``"linear"`` (the values as stored) or
    ``"srgb"`` (decoded to linear 0..1). Formats as :func:`read_image_data`; raises
    :class:`ImageReadError` (one line naming the file) otherwise, and for a colour image without
    ``channel``.
    """
    path, _ = check_image_file(path)
    if channel is not None and channel not in IMAGE_CHANNELS:
        raise ImageReadError(f"--channel = {channel!r}: allowed {', '.join(IMAGE_CHANNELS)}")
    if encoding not in ("linear", "srgb"):
        raise ImageReadError(f"encoding = {encoding!r}: allowed 'linear', 'srgb'")
    try:
        arr, names = read_image_data(path)
    except Exception as exc:
        raise ImageReadError(f"{path}: cannot read image ({' '.join(str(exc).split())[:120]})") from exc
    arr = np.asarray(arr)
    is_int = np.issubdtype(arr.dtype, np.integer)
    if not (is_int or np.issubdtype(arr.dtype, np.floating)):
        raise ImageReadError(f"{path}: unsupported pixel type {arr.dtype}")
    planes, rgb = _select(arr, names, channel, path)
    raw = planes.astype(np.float64)
    top = int(np.iinfo(arr.dtype).max) if is_int else None
    vals = srgb_to_linear(raw / (top or 1)) if encoding == "srgb" else raw
    if rgb:
        vals = vals @ np.asarray(ISO12233_LUMA)
    return ChannelImage(vals, raw.max(axis=-1) if rgb else raw, top, channel, encoding)


def image_shape(path: str | os.PathLike[str]) -> tuple[int, ...]:
    """The array shape of an image file from its header, without decoding the pixels (for the
    up-front memory estimate). Same formats as :func:`read_image`; raises
    :class:`ImageReadError` (one line) for a missing, unsupported or unreadable file."""
    path, suffix = check_image_file(path)
    try:
        if suffix == ".npy":
            return tuple(np.load(path, mmap_mode="r", allow_pickle=False).shape)
        if suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                return tuple(tif.series[0].shape)
        if suffix in (".png", ".bmp", ".jpg", ".jpeg"):
            from PIL import Image

            with Image.open(path) as img:
                bands = len(img.getbands())
                return (img.height, img.width) if bands == 1 else (img.height, img.width, bands)
        if suffix == ".exr":
            import OpenEXR

            with OpenEXR.File(str(path), header_only=True) as f:
                (x0, y0), (x1, y1) = f.header()["dataWindow"]
                return (int(y1 - y0 + 1), int(x1 - x0 + 1))
    except Exception as exc:  # the readers raise many kinds for a broken file
        detail = " ".join(str(exc).split())[:120]
        raise ImageReadError(f"{path}: cannot read image header ({detail})") from None
    raise AssertionError(suffix)  # check_image_file allows only the suffixes handled above
