"""File input/output with metadata: atomic writes, EXR, TIFF, PNG, NPY, JSON, CSV, text and
EMVA 1288 descriptor files.

Every file carries its provenance in one format (the dict of
:func:`bench_sim.experiments.provenance.provenance`: ``version``, ``seed``, ``config_sha256``,
``config``): as a JSON attribute (EXR header, TIFF ImageDescription, PNG ``tEXt`` chunk
``bench_sim``), as ``#`` comment lines (CSV, EMVA descriptors), or as keys (JSON).

Every writer goes through :func:`atomic_path`: the file is written under a temporary name in the
destination folder and renamed into place only when complete, so a failure never leaves a
partial output behind.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError

__all__ = [
    "atomic_path",
    "output_set",
    "check_output_dir",
    "check_free_space",
    "format_bytes",
    "OUTPUT_MARKER",
    "write_json",
    "read_json",
    "write_exr",
    "read_exr",
    "write_tiff16",
    "write_png",
    "write_figure_png",
    "read_png_text",
    "write_text",
    "write_csv",
    "write_emva_descriptor",
    "read_image",
    "sha256_text",
    "ImageReadError",
]


class ImageReadError(BenchSimError):
    """An input image file that cannot be read or is not of a supported kind."""


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file keeps the destination's suffix (some writers choose the format from it).
    On any exception the temporary file is removed and ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


#: File written last into every output folder made by :func:`output_set`; its presence marks a
#: complete set, and only folders holding it (or empty ones) are ever replaced by a rerun.
OUTPUT_MARKER = ".bench-sim-output.json"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_temporaries(out: Path) -> None:
    """Remove ``.NAME.partial-PID-*`` / ``.NAME.old-PID-*`` folders beside ``out`` whose process
    is gone (left by a killed run)."""
    for cand in out.parent.glob(f".{out.name}.*-*"):
        parts = cand.name[len(out.name) + 2 :].split("-")
        if len(parts) < 2 or parts[0] not in ("partial", "old") or not parts[1].isdigit():
            continue
        if not _pid_alive(int(parts[1])):
            shutil.rmtree(cand, ignore_errors=True)


def check_output_dir(out: str | os.PathLike[str], what: str = "--out") -> Path:
    """Check, before any computation, that ``out`` can receive an output set.

    Returns the resolved path. Raises :class:`BenchSimError` (one line) when ``out`` is a file,
    lies under a file, is a non-empty folder that bench_sim did not write, or its parent is not
    writable.
    """
    out = Path(out).expanduser().resolve()
    for anc in (out, *out.parents):
        if anc.exists():
            if anc.is_file() or not anc.is_dir():
                raise BenchSimError(f"{what} = {str(out)!r}: {anc} is a file, not a folder")
            break
    if out.is_dir() and any(out.iterdir()) and not (out / OUTPUT_MARKER).is_file():
        raise BenchSimError(
            f"{what} = {str(out)!r}: folder exists, is not empty and was not written by bench_sim "
            "(a rerun replaces the whole folder): choose a new or empty folder"
        )
    parent = out.parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BenchSimError(f"{what} = {str(out)!r}: {parent} is not writable")
    return out


@contextlib.contextmanager
def output_set(
    out: str | os.PathLike[str], record: Mapping[str, Any] | None = None, what: str = "--out"
) -> Iterator[Path]:
    """Write a set of output files as one: yield a temporary folder, rename it onto ``out``.

    The folder is created beside ``out`` (same file system) as ``.NAME.partial-PID-XXXX``. When
    the block completes, :data:`OUTPUT_MARKER` (``record`` as JSON) is written last and the folder
    replaces ``out`` whole: files of an earlier run never mix with the new ones. On any exception
    (Ctrl-C included) the temporary folder is removed and ``out`` keeps its previous complete set
    (or stays absent). Temporaries of killed runs are removed by the next run.

    Parameters
    ----------
    out
        Destination folder. It must not exist, be empty, or hold an earlier bench_sim output
        set (see :func:`check_output_dir`).
    record
        Content of the completion record (command, version, ...). No wall-clock times in it, so
        two runs with the same config and seed give identical files.
    what
        Name of the option or argument for error messages.
    """
    out = check_output_dir(out, what)
    out.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(out)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-{os.getpid()}-", dir=out.parent))
    except OSError as exc:
        raise BenchSimError(f"{what} = {str(out)!r}: cannot create a folder there ({exc.strerror})") from None
    try:
        yield tmp
        write_json(tmp / OUTPUT_MARKER, dict(record or {}))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp creates 0700
        old: Path | None = None
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-{os.getpid()}-", dir=out.parent))
            os.replace(out, old / "set")
        os.replace(tmp, out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def format_bytes(n: float) -> str:
    """``n`` bytes for a message: ``'512 B'``, ``'3.4 MiB'``, ``'2.1 TiB'`` (binary prefixes)."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover - unreachable


def check_free_space(
    out: str | os.PathLike[str], needed_bytes: int, what: str = "--out", detail: str = ""
) -> int:
    """Refuse, before any computation, an output that would not fit on its file system.

    ``needed_bytes`` is the caller's estimate of what it will write under ``out`` (an upper
    bound: e.g. uncompressed array sizes). Raises :class:`BenchSimError` (one line) when it
    exceeds the free space of the file system holding ``out`` (or its nearest existing parent);
    returns the free bytes otherwise. ``detail`` (e.g. ``"16 samples x 3.5 MiB"``) is shown in
    the message.
    """
    out = Path(out).expanduser().resolve()
    anc = out
    while not anc.exists():
        anc = anc.parent
    free = shutil.disk_usage(anc).free
    if needed_bytes > free:
        how = f" ({detail})" if detail else ""
        raise BenchSimError(
            f"{what} = {str(out)!r}: needs about {format_bytes(needed_bytes)}{how} but its file system "
            f"has {format_bytes(free)} free: free space, choose another disk or make less"
        )
    return int(free)


def sha256_text(text: str) -> str:
    """SHA-256 hex digest of a UTF-8 string."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_json(path: str | os.PathLike[str], data: Mapping[str, Any]) -> Path:
    """Write ``data`` as indented, key-sorted JSON, atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n")
    return path


def read_json(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a JSON file."""
    return json.loads(Path(path).read_text())


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
        header["bench_sim"] = json.dumps(metadata, sort_keys=True, default=_json_default)
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
    desc = json.dumps(metadata or {}, sort_keys=True, default=_json_default)
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, arr.astype(np.uint16), description=desc, metadata=None)
    return Path(path)


def _png_info(metadata: Mapping[str, Any] | None) -> Any:
    from PIL import PngImagePlugin

    info = PngImagePlugin.PngInfo()
    if metadata is not None:
        info.add_text("bench_sim", json.dumps(metadata, sort_keys=True, default=_json_default))
    return info


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
        img.save(tmp, format="PNG", pnginfo=_png_info(metadata))
    return Path(path)


def write_figure_png(
    path: str | os.PathLike[str], fig: Any, metadata: Mapping[str, Any] | None = None, dpi: float = 110
) -> Path:
    """Render a matplotlib figure to PNG with the ``bench_sim`` text chunk (Pillow ``PngInfo``)
    and close it."""
    import io as _io

    import matplotlib.pyplot as plt

    buf = _io.BytesIO()  # encoded once, with the text chunk (Pillow's PngInfo through matplotlib)
    fig.savefig(buf, format="png", dpi=dpi, pil_kwargs={"pnginfo": _png_info(metadata)})
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


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write a text file atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _comment_lines(metadata: Mapping[str, Any] | None) -> list[str]:
    """Provenance as ``#`` lines: ``# version ... seed ... config_sha256 ...`` and the JSON."""
    if not metadata:
        return []
    head = " ".join(f"{k} {metadata[k]}" for k in ("version", "seed", "config_sha256") if k in metadata)
    return [f"# bench_sim {head}".rstrip(), "# provenance: " + json.dumps(
        metadata, sort_keys=True, default=_json_default
    )]


def write_csv(
    path: str | os.PathLike[str],
    header: list[str],
    rows: list[list[Any]],
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a CSV table: provenance ``#`` lines, the header, the rows (floats to 10 digits).

    Readers: ``pandas.read_csv(path, comment="#")``.
    """
    import csv
    import io as _io

    buf = _io.StringIO()
    buf.writelines(line + "\n" for line in _comment_lines(metadata))
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.10g}" if isinstance(v, float) else v for v in r])
    return write_text(path, buf.getvalue())


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
    lines = ([f"# {title}"] if title else []) + _comment_lines(metadata)
    lines += ["v 4.0", f"n {int(bits)} {int(width)} {int(height)}"]
    for exposure_ns, photons, names in bright:
        lines.append(f"b {exposure_ns:.3f} {photons:.9g}")
        lines += [f"i {n}" for n in names]
    for exposure_ns, names in dark:
        lines.append(f"d {exposure_ns:.3f}")
        lines += [f"i {n}" for n in names]
    return write_text(path, "\n".join(lines) + "\n")


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a single-channel image as a float64 2-D array.

    Supported: 8/16-bit grayscale TIFF and PNG, single-channel (or first-channel) EXR, and NPY.
    Raises :class:`ImageReadError` with the file name for anything else.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageReadError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            arr = np.load(path, allow_pickle=False)
        elif suffix == ".exr":
            channels, _ = read_exr(path)
            name = next((n for n in ("Y", "R", "gray") if n in channels), sorted(channels)[0])
            arr = channels[name]
        elif suffix in (".tif", ".tiff"):
            import tifffile

            arr = tifffile.imread(path)
        elif suffix == ".png":
            import imageio.v3 as iio

            arr = iio.imread(path)
        else:
            raise ImageReadError(
                f"{path}: unsupported file type '{suffix}' (allowed: .tif, .tiff, .png, .exr, .npy)"
            )
    except ImageReadError:
        raise
    except Exception as exc:
        raise ImageReadError(f"{path}: cannot read image ({exc})") from exc
    arr = np.asarray(arr)
    if arr.ndim != 2:
        raise ImageReadError(f"{path}: expected a single-channel 2-D image, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ImageReadError(f"{path}: unsupported pixel type {arr.dtype}")
    return arr.astype(np.float64)
