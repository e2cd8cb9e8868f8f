"""Targets from image files and from seeded generators (bench_sim.rig.target_sources)."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.config import ConfigError, load_config, with_overrides
from bench_sim.io import write_exr
from bench_sim.rig.target_sources import (
    REC709_LUMA,
    TargetImageError,
    fit_to_panel,
    panel_map,
    read_target_image,
    srgb_to_linear,
)


def _target(**kw):
    return with_overrides(load_config(), {"target": {"panel_lines": 32, "panel_columns": 48, **kw}}).target


def _write(path, arr):
    suffix = path.suffix
    if suffix == ".npy":
        np.save(path, arr)
    elif suffix == ".exr":
        write_exr(path, {"Y": arr})
    elif suffix in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, arr)
    else:
        import imageio.v3 as iio

        iio.imwrite(path, arr)
    return path


@pytest.mark.parametrize(
    "name, dtype",
    [("a.png", np.uint8), ("a.png", np.uint16), ("a.tif", np.uint16), ("a.tif", np.float32),
     ("a.exr", np.float32), ("a.npy", np.float64), ("a.npy", np.uint8)],
)
def test_every_file_kind_reads_as_linear_values(tmp_path, name, dtype):
    ramp = np.linspace(0, 1, 48)[None, :].repeat(32, axis=0)
    if np.issubdtype(dtype, np.integer):
        top = np.iinfo(dtype).max
        arr = np.round(ramp * top).astype(dtype)
        want = srgb_to_linear(arr / top)  # integer files default to sRGB
    else:
        arr = ramp.astype(dtype)
        want = arr.astype(np.float64)  # float files default to linear
    path = _write(tmp_path / name, arr)
    vals, is_int = read_target_image(_target(layout="image", image=str(path)))
    assert is_int == bool(np.issubdtype(dtype, np.integer))
    np.testing.assert_allclose(vals, want, atol=1e-6)


@pytest.mark.physics
def test_srgb_decoding_and_rec709_luminance(tmp_path):
    # sRGB 188/255 is ~50 % linear; pure green carries 0.7152 of the luminance
    rgb = np.zeros((4, 6, 3), dtype=np.uint8)
    rgb[..., 1] = 188
    path = _write(tmp_path / "g.png", rgb)
    y, _ = read_target_image(_target(layout="image", image=str(path)))
    assert y == pytest.approx(np.full((4, 6), REC709_LUMA[1] * srgb_to_linear(188 / 255)))
    assert srgb_to_linear(188 / 255) == pytest.approx(0.5, abs=0.01)
    green = _target(layout="image", image=str(path), image_channel="G", image_encoding="linear")
    g, _ = read_target_image(green)
    assert g == pytest.approx(np.full((4, 6), 188 / 255))
    with pytest.raises(TargetImageError, match="image_channel = 'Q'"):
        read_target_image(_target(layout="image", image=str(path), image_channel="Q"))


def test_integer_images_map_into_the_reflectance_range(tmp_path):
    arr = np.zeros((32, 48), dtype=np.uint8)
    arr[:, 24:] = 255
    path = _write(tmp_path / "half.png", arr)
    m = panel_map(_target(layout="image", image=str(path), reflectance_min=0.05, reflectance_max=0.8), None)
    assert m.shape == (32 * 4, 48 * 4)
    np.testing.assert_allclose(np.unique(m), [0.05, 0.8], rtol=1e-6)


@pytest.mark.parametrize("fit", ["stretch", "crop", "tile"])
def test_fits_fill_the_texel_grid(fit):
    img = np.arange(20 * 30, dtype=np.float64).reshape(20, 30) / 600
    out = fit_to_panel(img, fit, 16, 48, 2)
    assert out.shape == (32, 96)
    if fit == "stretch":  # area averaging keeps the mean
        assert out.mean() == pytest.approx(img.mean(), rel=1e-3)
    if fit == "tile":  # one image pixel per object pixel (q texels), repeated across
        assert np.array_equal(out[:, :60:2], np.repeat(img[:16], 2, axis=0)[:, :30])
        assert np.array_equal(out[:, 60:96], out[:, :36])
    if fit == "crop":  # aspect kept: scaled by 96 / 30, the middle rows kept
        assert out[:, 0].std() > 0 and abs(out.mean() - img.mean()) < 0.05


@pytest.mark.parametrize(
    "content, problem",
    [
        (None, "no such file"),
        (b"not an image at all", "cannot read"),
        (np.array([[0.5, np.nan], [0.1, 0.2]], dtype=np.float32), "NaN or inf"),
        (np.array([[0.5, 1.5], [0.1, 0.2]], dtype=np.float32), "outside 0..1"),
        (np.array([[0.5, -0.1], [0.1, 0.2]], dtype=np.float64), "outside 0..1"),
    ],
)
def test_bad_image_files_name_the_file_and_problem(tmp_path, content, problem):
    path = tmp_path / ("bad.tif" if not isinstance(content, np.ndarray) else "bad.npy")
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, np.ndarray):
        np.save(path, content)
    with pytest.raises(TargetImageError, match=problem) as exc:
        read_target_image(_target(layout="image", image=str(path)))
    assert str(path.name) in str(exc.value) and "\n" not in str(exc.value)


def test_image_path_is_relative_to_the_config_file(tmp_path):
    from bench_sim.config import DEFAULT_CONFIG_PATH

    (tmp_path / "img").mkdir()
    _write(tmp_path / "img" / "t.png", np.zeros((4, 4), np.uint8))
    (tmp_path / "bench.toml").write_text(
        f'base = "{DEFAULT_CONFIG_PATH}"\n[target]\nlayout = "image"\nimage = "img/t.png"\n'
    )
    cfg = load_config(tmp_path / "bench.toml")
    assert cfg.target.image == str((tmp_path / "img" / "t.png").resolve())
    with pytest.raises(ConfigError, match="needs target.image"):
        with_overrides(load_config(), {"target": {"layout": "image"}})


@pytest.mark.parametrize("layout", ["dead_leaves", "slanted_edges", "random_bars"])
def test_generators_are_seeded_and_in_range(layout):
    cfg = _target(layout=layout)
    a = panel_map(cfg, np.random.default_rng(1))
    b = panel_map(cfg, np.random.default_rng(1))
    c = panel_map(cfg, np.random.default_rng(2))
    assert a.shape == (32 * 4, 48 * 4) and np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.isfinite(a).all()
    assert cfg.reflectance_min <= a.min() and a.max() <= cfg.reflectance_max
    if layout == "random_bars":  # constant across the track, widths within the bounds
        assert np.all(a == a[:, :1])
        edges = np.nonzero(np.diff(a[:, 0]))[0] + 1
        widths = np.diff(edges) / cfg.texels_per_pixel
        assert widths.min() >= cfg.bar_width_min_px - 0.25 and widths.max() <= cfg.bar_width_max_px + 0.25
    if layout == "dead_leaves":  # many levels, fully covered
        assert len(np.unique(a)) > 50


def test_slanted_edges_lie_near_five_degrees():
    cfg = _target(layout="slanted_edges", panel_lines=64, panel_columns=64, edge_cell_px=64)
    m = panel_map(cfg, np.random.default_rng(3))  # one cell: one rotated square
    dark = m < 0.5 * (m.min() + m.max())
    ys, xs = np.nonzero(dark)
    # principal axes of the square's texels: a square's inertia is isotropic, so use its edge:
    # the leftmost dark texel of every row traces the left edge
    rows = np.unique(ys)
    mid = rows[len(rows) // 4 : 3 * len(rows) // 4]
    left = np.array([xs[ys == r].min() for r in mid])
    slope = np.polyfit(mid, left, 1)[0]
    angle = np.degrees(np.arctan(abs(slope)))
    assert 5.0 - cfg.edge_angle_jitter_deg - 0.5 <= angle <= 5.0 + cfg.edge_angle_jitter_deg + 0.5
    assert dark.mean() == pytest.approx(0.25, abs=0.02)  # half the cell side squared
