"""Closed-form geometry and kinematics of the rig.

World frame: the drum axis is the ``x`` axis, the camera's lens centre sits at
``(0, 0, R + d)`` and looks along ``-z`` at the surface point ``(0, 0, R)``; image "up" is
``+y``. Sensor row 0 is the top row of the image and rows count downwards; a scene line enters
at row 0 and leaves after row ``M - 1`` (the surface moves down the image).

The drum angle of a surface point is ``theta = atan2(-y, z)`` (0 facing the camera, growing
downwards in the image). The drum turns so that material at ``theta`` moves to larger
``theta``; a material point's *along-track coordinate* is ``y_mat = R * (omega * t - theta)
+ y_offset`` [m], fixed to the material, so scene line ``j`` (seen by row 0 at the start of
frame ``j``) has ``y_mat = j * delta`` with ``delta = R * omega * T`` the surface travel per line
period ``T``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench_sim.config import BenchConfig

__all__ = ["RigGeometry", "rig_geometry", "row_surface_angles", "surface_angles"]


@dataclass(frozen=True)
class RigGeometry:
    """Derived geometry of a bench (all SI).

    Attributes
    ----------
    radius_m
        Drum radius R.
    camera_distance_m
        Lens centre to drum axis, ``R + working distance``.
    image_distance_m
        Lens to sensor (thin-lens equation at the focus distance).
    magnification
        ``image_distance / working_distance`` on the optical axis.
    object_pixel_m
        Pixel pitch projected onto the drum surface on the optical axis.
    fov_x_deg
        Full horizontal field of view (across the columns).
    omega_rad_s
        Drum angular speed, including the sync error.
    delta_m
        Surface travel per line period ``R * omega * T`` (= object pixel x (1 + sync_error)).
    smear_m
        Surface travel during the integration time ``R * omega * t_int``.
    row_theta_rad
        Drum angle seen by the centre of each sensor row (chief ray), shape (M,).
    y_offset_m
        Constant making scene line ``j`` sit at ``y_mat = j * delta`` (centre of its exposure).
    """

    radius_m: float
    camera_distance_m: float
    image_distance_m: float
    magnification: float
    object_pixel_m: float
    fov_x_deg: float
    omega_rad_s: float
    delta_m: float
    smear_m: float
    line_period_s: float
    t_int_s: float
    row_theta_rad: np.ndarray
    y_offset_m: float

    def y_material(self, theta_rad: np.ndarray, t_s: float | np.ndarray) -> np.ndarray:
        """Along-track material coordinate [m] of a surface point at drum angle ``theta`` at
        time ``t``."""
        return self.radius_m * (self.omega_rad_s * np.asarray(t_s) - np.asarray(theta_rad)) + (
            self.y_offset_m
        )


def row_surface_angles(
    rows: int, pixel_pitch_m: float, image_distance_m: float, radius_m: float, camera_distance_m: float
) -> np.ndarray:
    """Drum angle ``theta`` [rad] hit by the chief ray through each row centre (pinhole model).

    Row ``i`` centre lies ``(i + 0.5 - rows/2) * pitch`` below the image centre; its chief ray
    leaves the lens centre ``(0, 0, D)`` downwards at ``alpha = atan(offset / image_distance)``
    and meets the circle ``y^2 + z^2 = R^2`` (nearest root).
    """
    offset = (np.arange(rows) + 0.5 - rows / 2.0) * pixel_pitch_m
    return surface_angles(offset, image_distance_m, radius_m, camera_distance_m)


def surface_angles(
    offset_m: np.ndarray, image_distance_m: float, radius_m: float, camera_distance_m: float
) -> np.ndarray:
    """Drum angle ``theta`` [rad] hit by the chief ray through a point ``offset_m`` below the image
    centre (any array; :func:`row_surface_angles` evaluates it at the row centres)."""
    offset = np.asarray(offset_m, dtype=np.float64)
    alpha = np.arctan2(offset, image_distance_m)
    dy, dz = -np.sin(alpha), -np.cos(alpha)
    # |(0, D) + s (dy, dz)|^2 = R^2  ->  s^2 + 2 s D dz + D^2 - R^2 = 0
    b = camera_distance_m * dz
    disc = b * b - (camera_distance_m**2 - radius_m**2)
    if np.any(disc < 0):
        raise ValueError("some sensor rows do not see the drum")
    s = -b - np.sqrt(disc)
    y, z = s * dy, camera_distance_m + s * dz
    return np.arctan2(-y, z)


def rig_geometry(cfg: BenchConfig) -> RigGeometry:
    """Derive the rig's geometry and kinematics from a config.

    The drum's angular speed makes the surface image move one pixel pitch per line period on
    the optical axis, detuned by ``timing.sync_error``:
    ``omega = (1 + e) * object_pixel / (R * T)``.
    """
    lens, sensor, timing = cfg.lens, cfg.sensor, cfg.timing
    R = cfg.drum.radius_m
    D = R + lens.working_distance_m
    s_img = lens.image_distance_m
    mag = lens.magnification
    p_obj = sensor.pixel_pitch_m / mag
    fov_x = 2.0 * math.degrees(math.atan(0.5 * sensor.columns * sensor.pixel_pitch_m / s_img))
    T = timing.line_period_s
    t_int = timing.t_int_s
    omega = (1.0 + timing.sync_error) * p_obj / (R * T)
    delta = R * omega * T
    smear = R * omega * t_int
    theta = row_surface_angles(sensor.rows, sensor.pixel_pitch_m, s_img, R, D)
    # line j = material seen by row 0 at frame j, centred in its exposure window
    y_offset = R * float(theta[0]) - 0.5 * smear
    return RigGeometry(
        radius_m=R,
        camera_distance_m=D,
        image_distance_m=s_img,
        magnification=mag,
        object_pixel_m=p_obj,
        fov_x_deg=fov_x,
        omega_rad_s=omega,
        delta_m=delta,
        smear_m=smear,
        line_period_s=T,
        t_int_s=t_int,
        row_theta_rad=theta,
        y_offset_m=y_offset,
    )
