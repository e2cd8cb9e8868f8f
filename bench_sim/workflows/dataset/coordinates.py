"""Physical coordinates and CF-style metadata of a dataset's store (``data.zarr``).

- :func:`physical_coords`: ``along_track_mm`` and ``time_s`` on ``line``, ``across_track_mm`` on
  ``column`` (from :func:`bench_sim.rig.geometry.rig_geometry` of the dataset's base bench).
  Scene line ``j`` is the drum material at ``j * delta`` along the track (``delta`` the surface
  travel per line period), first exposed by row 0 at ``t = j T`` (``T`` the line period, frame
  ``j`` starting at ``j T``); column ``n`` sees ``(n - (N - 1) / 2) * p_obj`` across the track
  (``p_obj`` the pixel pitch projected on the drum on the optical axis). Samples that randomise
  geometry or timing keys differ from these nominal values (their config is in their record).
- :func:`variable_attrs`: ``units``, ``long_name`` and the pedestal convention of each variable:
  ``pedestal_included = "yes"`` on the stage words and their expectations (``dn``, ``mean_dn``,
  ``linear_dn`` carry the DTDI pedestal ``dtdi.pedestal_dn``), ``"no"`` on ``gamma_hdr`` and
  ``gamma_hdr_truth`` (removed before eq. 11), ``"not applicable"`` elsewhere.
- :func:`constant_attrs`: the sensor (EMVA 1288 model) and DTDI constants as store attributes
  (``sensor_<key>``, ``dtdi_<key>``, ``t_int_s``, ``line_period_s``, ``mu1``, ``mu2``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.rig.geometry import rig_geometry

__all__ = ["PEDESTAL_INCLUDED", "physical_coords", "variable_attrs", "constant_attrs"]

#: Variables whose values carry the DTDI pedestal (the others do not, or are not levels)
PEDESTAL_INCLUDED = {
    "dn": "yes", "mean_dn": "yes", "linear_dn": "yes", "gamma_hdr": "no", "gamma_hdr_truth": "no",
}


def physical_coords(cfg: BenchConfig) -> dict[str, tuple[str, np.ndarray, dict[str, str]]]:
    """Coordinate name -> (dimension, values, attributes) in physical units (module docstring)."""
    geom = rig_geometry(cfg)
    lines = np.arange(cfg.lines, dtype=np.float64)
    cols = np.arange(cfg.sensor.columns, dtype=np.float64)
    across = (cols - 0.5 * (cfg.sensor.columns - 1)) * geom.object_pixel_m * 1e3
    return {
        "along_track_mm": ("line", lines * geom.delta_m * 1e3, {
            "units": "mm", "long_name": "along-track position of the scene line on the drum surface "
            "(line * surface travel per line period; nominal, of the base bench)",
            "standard_name": "projection_y_coordinate"}),
        "time_s": ("line", lines * geom.line_period_s, {
            "units": "s", "long_name": "start of the line's first exposure (row 0), from frame 0 "
            "(line * line period; nominal, of the base bench)", "standard_name": "time"}),
        "across_track_mm": ("column", across, {
            "units": "mm", "long_name": "across-track position of the column on the drum surface, from "
            "the optical axis (projected pixel pitch; nominal, of the base bench)",
            "standard_name": "projection_x_coordinate"}),
    }


def variable_attrs(name: str, units: str, long_name: str, pedestal_dn: float) -> dict[str, Any]:
    """CF-style attributes of a variable with the pedestal convention (module docstring)."""
    attrs: dict[str, Any] = {"units": units, "long_name": long_name,
                             "pedestal_included": PEDESTAL_INCLUDED.get(name, "not applicable")}
    if name in PEDESTAL_INCLUDED:
        attrs["pedestal_dn"] = float(pedestal_dn)
    return attrs


def constant_attrs(cfg: BenchConfig) -> dict[str, Any]:
    """The sensor and DTDI constants of a bench as flat attributes (numbers, booleans, text)."""
    out: dict[str, Any] = {}
    for prefix, section in (("sensor", cfg.sensor), ("dtdi", cfg.dtdi)):
        for key, value in section.model_dump(mode="json").items():
            if isinstance(value, bool | int | float | str):
                out[f"{prefix}_{key}"] = value
    geom = rig_geometry(cfg)
    out.update(
        t_int_s=float(geom.t_int_s), line_period_s=float(geom.line_period_s),
        object_pixel_m=float(geom.object_pixel_m), delta_m=float(geom.delta_m),
        fusion_mu1=int(cfg.fusion.mu1), fusion_mu2=int(cfg.fusion.mu2),
    )
    return out
