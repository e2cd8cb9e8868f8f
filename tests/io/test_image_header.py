"""Image sizes from the header (:mod:`bench_sim.io.image_header`): the same width and height as
the libraries that decode the files, for every format; a header claiming too many pixels, or
none, refused in one line before any decoder runs; special files named as such."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest

from bench_sim.io import ImageReadError, read_image
from bench_sim.io.image_header import MAX_IMAGE_PIXELS, header_size, image_size_problem
from bench_sim.io.images import IMAGE_SUFFIXES
from bench_sim.io.input_files import input_file_problem

#: (height, width) of the real images written for the comparison
SHAPES = [(1, 1), (3, 7), (37, 5), (64, 300)]


def _pillow(path: Path, shape: tuple[int, int], mode: str, **save: object) -> Path:
    from PIL import Image

    channels = {"L": (), "RGB": (3,)}[mode]
    arr = np.random.default_rng(0).integers(0, 255, (*shape, *channels), dtype=np.uint8)
    Image.fromarray(arr, mode).save(path, **save)
    return path


WRITERS = {
    "png gray": lambda p, s: _pillow(p.with_suffix(".png"), s, "L"),
    "png rgb": lambda p, s: _pillow(p.with_suffix(".png"), s, "RGB"),
    "bmp 8-bit": lambda p, s: _pillow(p.with_suffix(".bmp"), s, "L"),
    "bmp 24-bit": lambda p, s: _pillow(p.with_suffix(".bmp"), s, "RGB"),
    "jpeg baseline": lambda p, s: _pillow(p.with_suffix(".jpg"), s, "RGB", quality=90),
    "jpeg progressive": lambda p, s: _pillow(p.with_suffix(".jpeg"), s, "L", progressive=True),
    "tiff": lambda p, s: _tifffile(p.with_suffix(".tif"), s),
    "exr": lambda p, s: _exr(p.with_suffix(".exr"), s),
    "npy": lambda p, s: _npy(p.with_suffix(".npy"), s),
}


def _tifffile(path: Path, shape: tuple[int, int]) -> Path:
    import tifffile

    tifffile.imwrite(path, np.zeros(shape, np.uint16))
    return path


def _exr(path: Path, shape: tuple[int, int]) -> Path:
    from bench_sim.io import write_exr

    write_exr(path, {"Y": np.zeros(shape, np.float32)})
    return path


def _npy(path: Path, shape: tuple[int, int]) -> Path:
    np.save(path, np.zeros(shape, np.uint16))
    return path


def _decoded_shape(path: Path) -> tuple[int, int]:
    """(height, width) as the decoding library sees the file."""
    suffix = path.suffix.lower()
    if suffix in (".png", ".bmp", ".jpg", ".jpeg"):
        from PIL import Image

        with Image.open(path) as img:
            return img.height, img.width
    if suffix == ".tif":
        import tifffile

        return tuple(tifffile.imread(path).shape[:2])  # type: ignore[return-value]
    if suffix == ".exr":
        from bench_sim.io import read_exr

        return next(iter(read_exr(path)[0].values())).shape  # type: ignore[return-value]
    return tuple(np.load(path).shape)  # type: ignore[return-value]


@pytest.mark.parametrize("shape", SHAPES, ids=[f"{h}x{w}" for h, w in SHAPES])
@pytest.mark.parametrize("kind", list(WRITERS))
def test_the_header_size_is_the_decoded_size(tmp_path: Path, kind: str, shape: tuple[int, int]) -> None:
    path = WRITERS[kind](tmp_path / "img", shape)
    assert header_size(path) == _decoded_shape(path) == shape
    assert image_size_problem(path) is None


def test_a_bottom_up_and_a_top_down_bmp_have_the_same_size(tmp_path: Path) -> None:
    path = _pillow(tmp_path / "a.bmp", (5, 9), "L")
    data = bytearray(path.read_bytes())
    height = struct.unpack("<i", data[22:26])[0]
    data[22:26] = struct.pack("<i", -height)  # top-down rows: a negative height
    (tmp_path / "b.bmp").write_bytes(bytes(data))
    assert header_size(path) == header_size(tmp_path / "b.bmp") == (5, 9)


# ---------------------------------------------------------------- headers claiming too much


def _claim_png(folder: Path, width: int, height: int) -> Path:
    data = bytearray(_pillow(folder / "c.png", (2, 2), "L").read_bytes())
    data[16:24] = struct.pack(">II", width, height)  # IHDR (its CRC is not checked before decoding)
    (folder / "c.png").write_bytes(bytes(data))
    return folder / "c.png"


def _claim_bmp(folder: Path, width: int, height: int) -> Path:
    data = bytearray(_pillow(folder / "c.bmp", (2, 2), "L").read_bytes())
    data[18:26] = struct.pack("<ii", width, height)
    (folder / "c.bmp").write_bytes(bytes(data))
    return folder / "c.bmp"


def _claim_jpeg(folder: Path, width: int, height: int) -> Path:
    data = bytearray(_pillow(folder / "c.jpg", (2, 2), "L").read_bytes())
    i = data.index(b"\xff\xc0")  # the baseline frame header
    data[i + 5 : i + 9] = struct.pack(">HH", height, width)
    (folder / "c.jpg").write_bytes(bytes(data))
    return folder / "c.jpg"


def _claim_tiff(folder: Path, width: int, height: int) -> Path:
    import tifffile

    path = folder / "c.tif"
    tifffile.imwrite(path, np.zeros((2, 2), np.uint16))
    data = bytearray(path.read_bytes())
    ifd = struct.unpack("<I", data[4:8])[0]
    for k in range(struct.unpack("<H", data[ifd : ifd + 2])[0]):
        entry = ifd + 2 + 12 * k
        tag, typ = struct.unpack("<HH", data[entry : entry + 4])
        if tag in (256, 257):  # ImageWidth, ImageLength as LONG values
            data[entry + 2 : entry + 12] = struct.pack("<HII", 4, 1, width if tag == 256 else height)
    path.write_bytes(bytes(data))
    return path


def _claim_exr(folder: Path, width: int, height: int) -> Path:
    path = _exr(folder / "c.exr", (2, 2))
    data = bytearray(path.read_bytes())
    i = data.index(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    data[i : i + 16] = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    path.write_bytes(bytes(data))
    return path


def _claim_npy(folder: Path, width: int, height: int) -> Path:
    path = folder / "c.npy"
    with open(path, "wb") as f:  # the header alone: no pixel follows it
        np.lib.format.write_array_header_1_0(
            f, {"descr": "<u2", "fortran_order": False, "shape": (height, width)}
        )
    return path


CLAIMS = {"png": _claim_png, "bmp": _claim_bmp, "jpeg": _claim_jpeg, "tiff": _claim_tiff,
          "exr": _claim_exr, "npy": _claim_npy}


@pytest.mark.parametrize("kind", list(CLAIMS))
def test_a_header_claiming_too_many_pixels_is_refused_before_decoding(
    tmp_path: Path, kind: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    side = 60_000 if kind in ("jpeg",) else 100_000  # JPEG sizes are 16-bit
    path = CLAIMS[kind](tmp_path, side, side)
    assert header_size(path) == (side, side)
    problem = image_size_problem(path)
    assert problem is not None and f"{side} x {side} = {side * side} pixels" in problem
    assert side * side > MAX_IMAGE_PIXELS or kind in ("png", "bmp", "jpeg")  # those: Pillow's bound

    def no_decoder(*args: object, **kwargs: object) -> None:
        raise AssertionError("a decoder ran")

    monkeypatch.setattr("bench_sim.io.images.read_image_data", no_decoder)
    if path.suffix in IMAGE_SUFFIXES:  # the formats bench_sim reads: refused by its one check
        with pytest.raises(ImageReadError, match="pixels: more than"):
            read_image(path)


@pytest.mark.parametrize("kind", list(CLAIMS))
def test_an_empty_image_is_refused(tmp_path: Path, kind: str) -> None:
    path = CLAIMS[kind](tmp_path, 0, 7)
    problem = image_size_problem(path)
    if kind == "exr":  # OpenEXR itself refuses to open an empty data window
        assert problem is not None and problem.startswith("cannot read its header")
    else:
        assert problem == "empty image (0 x 7 pixels)"


def test_a_broken_header_is_one_line(tmp_path: Path) -> None:
    for name, data in (("a.png", b"\x89PNG\r\n"), ("b.bmp", b"XX" + bytes(30)), ("c.jpg", b"\xff\xd8\x00")):
        (tmp_path / name).write_bytes(data)
        problem = image_size_problem(tmp_path / name)
        assert problem is not None and problem.startswith("cannot read its header") and "\n" not in problem


# ---------------------------------------------------------------- special files


def test_special_files_are_named_as_such(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "dir").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "gone")
    (tmp_path / "file").write_text("x")
    fifo = "is a special file (a FIFO (named pipe)), not a regular file"
    assert input_file_problem(tmp_path / "fifo") == fifo
    assert input_file_problem("/dev/zero") == "is a special file (a character device), not a regular file"
    assert input_file_problem(tmp_path / "dir") == "is a folder, not a file"
    assert input_file_problem(tmp_path / "link") == "is a broken link"
    assert input_file_problem(tmp_path / "missing") == "no such file"
    assert input_file_problem(tmp_path / "file" / "x") is not None
    assert input_file_problem(tmp_path / "file") is None
