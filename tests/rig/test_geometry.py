"""Rig geometry and kinematics against closed forms; the ground truth behind the images."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.render.texture import ground_truth_reflectance, run_texture
from bench_sim.rig.geometry import rig_geometry
from tests.conftest import make_cfg, tiny_cfg

#: closed forms, invariants and seeded statistical tests (make test-fast)
pytestmark = pytest.mark.physics


def test_row_angles_follow_the_law_of_sines():
    """A chief ray leaving the lens at alpha below the axis meets the drum where
    sin(theta + alpha) = (D / R) sin(alpha) (triangle axis-lens-hit point)."""
    cfg = make_cfg()
    g = rig_geometry(cfg)
    rows = cfg.sensor.rows
    offset = (np.arange(rows) + 0.5 - rows / 2) * cfg.sensor.pixel_pitch_m
    alpha = np.arctan2(offset, g.image_distance_m)
    d_over_r = g.camera_distance_m / g.radius_m
    closed = np.arcsin(d_over_r * np.sin(alpha)) - alpha
    assert np.allclose(g.row_theta_rad, closed, rtol=0, atol=1e-12)


def test_surface_moves_one_pixel_per_line_on_axis_and_faster_off_axis():
    """On the axis one row spans one object pixel (pitch x working distance / image distance),
    so the drum speed omega = p_obj / (R T) moves the image one row per line period. Rows away
    from the axis see more surface per row: d theta / d alpha = (D/R) cos a / sqrt(1 - (D/R)^2
    sin^2 a) - 1 grows off axis (the curved surface), here by ~5e-4 at the edge rows."""
    cfg = make_cfg()
    g = rig_geometry(cfg)
    p_obj = cfg.sensor.pixel_pitch_m * cfg.lens.working_distance_m / g.image_distance_m
    assert g.object_pixel_m == pytest.approx(p_obj, rel=1e-12)
    arc_per_row = g.radius_m * np.diff(g.row_theta_rad)
    mid = cfg.sensor.rows // 2 - 1
    assert arc_per_row[mid] == pytest.approx(p_obj, rel=1e-6)
    assert g.delta_m == pytest.approx(p_obj, rel=1e-12)  # in sync
    k = g.camera_distance_m / g.radius_m

    def arc_per_offset(offset_m):  # R d theta / d offset = R (d theta / d alpha) cos^2(a) / s'
        a = np.arctan2(offset_m, g.image_distance_m)
        dtheta = k * np.cos(a) / np.sqrt(1 - (k * np.sin(a)) ** 2) - 1
        return g.radius_m * dtheta * np.cos(a) ** 2 / g.image_distance_m

    edge = arc_per_offset((1 - cfg.sensor.rows / 2) * cfg.sensor.pixel_pitch_m)  # between rows 0, 1
    excess = edge / arc_per_offset(0.0) - 1
    assert 1e-4 < excess < 1e-3
    assert arc_per_row[0] / arc_per_row[mid] - 1 == pytest.approx(excess, rel=0.02)
    off = rig_geometry(make_cfg(timing={"sync_error": 0.01}))
    assert off.delta_m == pytest.approx(1.01 * p_obj, rel=1e-12)


def test_ground_truth_is_the_target_behind_each_line():
    """The wedge patches of the ground truth carry exactly their printed reflectance."""
    cfg = tiny_cfg(sensor={"columns": 48}, target={"panel_lines": 96, "panel_columns": 48})
    g = rig_geometry(cfg)
    panel = run_texture(cfg, g, 0, 8).panel
    truth = ground_truth_reflectance(cfg, g, panel, 96)
    assert truth.shape == (96, 48)
    for p in panel.patches:
        l0, l1 = int(np.ceil(p.u0)), int(np.floor(p.u1))
        c0, c1 = int(np.ceil(p.v0)), int(np.floor(p.v1)) - 1
        if l1 - l0 >= 2 and c1 - c0 >= 1:
            inner = truth[l0 + 1 : l1 - 1, c0 + 1 : c1]
            if inner.size:
                assert np.allclose(inner, p.reflectance, rtol=1e-5), p.name
    uni = tiny_cfg(target={"layout": "uniform", "uniform_reflectance": 0.37})
    gu = rig_geometry(uni)
    flat = ground_truth_reflectance(uni, gu, run_texture(uni, gu, 0, 4).panel, 10)
    assert np.allclose(flat, 0.37)
