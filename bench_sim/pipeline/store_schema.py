"""The schema of a pass in files, one for ``simulate`` and the data sets: coordinates (with their
physical positions), attributes (the run and the sensor's constants), stored dtypes and chunks.

- :func:`pass_coords`: ``stage``, ``line``, ``column`` and the physical coordinates of
  :func:`physical_coords`: ``along_track_mm`` and ``time_s`` on ``line``, ``across_track_mm`` on
  ``column`` (from :func:`bench_sim.rig.geometry.rig_geometry` of the bench). Scene line ``j`` is
  the drum material at ``s0 + j * delta`` along the track (``delta`` the surface travel per line
  period), first exposed by row 0 at ``t = j T`` (``T`` the line period, frame ``j`` starting at
  ``j T``); column ``n`` sees ``x0 + (n - (N - 1) / 2) * p_obj`` across the track (``p_obj`` the
  pixel pitch projected on the drum on the optical axis). ``(x0, s0)`` is where the window sits
  on the rig (0, 0 for a bench's own view; a data set's sample may sit elsewhere).
- :func:`pass_attrs`: the config, seed, version, engine, the sensor's chain, and the sensor
  (EMVA 1288 model) and DTDI constants (:func:`constant_attrs`: ``sensor_<key>``,
  ``dtdi_<key>``, ``t_int_s``, ``line_period_s``, ``object_pixel_m``, ``delta_m``,
  ``fusion_mu1``, ``fusion_mu2``).
- :func:`store_chunks`: one stage (one sample) per chunk, all columns, lines in blocks of at most
  :data:`CHUNK_PIXELS` pixels.
- :func:`stored_dataset`: a pass's :class:`xarray.Dataset` in the stored dtypes
  (:meth:`bench_sim.pipeline.variables.Variable.stored_dtype`) with those chunks as its encoding.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from bench_sim.config import BenchConfig, config_sha256, config_to_toml_text
from bench_sim.pipeline.variables import VARIABLES_BY_NAME, pedestal_dn
from bench_sim.render.exposures import RenderSetup
from bench_sim.rig.geometry import rig_geometry
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.version import __version__

if TYPE_CHECKING:
    import xarray as xr

__all__ = [
    "COORD_ATTRS", "CHUNK_PIXELS", "physical_coords", "constant_attrs", "pass_coords", "pass_attrs",
    "store_chunks", "stored_dataset",
]

#: pixels of a chunk of a stored variable, at most (4 MiB of float32): whole images up to 1024 x 1024
CHUNK_PIXELS = 2**20

#: units and long names of the pass's index coordinates
COORD_ATTRS = {
    "line": {"units": "1", "long_name": "scene line (material at line * delta along the track)"},
    "column": {"units": "1", "long_name": "sensor column"},
    "stage": {"units": "1", "long_name": "DTDI stage m (rows summed)"},
}


def physical_coords(
    cfg: BenchConfig, *, across_m: float = 0.0, along_m: float = 0.0
) -> dict[str, tuple[str, np.ndarray, dict[str, str]]]:
    """Coordinate name -> (dimension, values, attributes) in physical units (module docstring);
    ``across_m``, ``along_m``: where the window's centre sits on the rig [m], across the track
    (along the drum axis) and along it (arc length on the drum surface) from the bench's view."""
    geom = rig_geometry(cfg)
    lines = np.arange(cfg.lines, dtype=np.float64)
    cols = np.arange(cfg.sensor.columns, dtype=np.float64)
    across = (float(across_m) + (cols - 0.5 * (cfg.sensor.columns - 1)) * geom.object_pixel_m) * 1e3
    return {
        "along_track_mm": ("line", (float(along_m) + lines * geom.delta_m) * 1e3, {
            "units": "mm", "long_name": "along-track position of the scene line on the drum surface "
            "(window offset + line * surface travel per line period)",
            "standard_name": "projection_y_coordinate"}),
        "time_s": ("line", lines * geom.line_period_s, {
            "units": "s", "long_name": "start of the line's first exposure (row 0), from frame 0 "
            "(line * line period)", "standard_name": "time"}),
        "across_track_mm": ("column", across, {
            "units": "mm", "long_name": "across-track position of the column on the drum surface "
            "(window offset + projected pixel pitch from the optical axis)",
            "standard_name": "projection_x_coordinate"}),
    }


def constant_attrs(cfg: BenchConfig) -> dict[str, Any]:
    """The sensor and DTDI constants of a bench as flat attributes (numbers, booleans, text)."""
    out: dict[str, Any] = {}
    for prefix, section in (("sensor", cfg.sensor), ("dtdi", cfg.dtdi)):
        for key, value in section.model_dump(mode="json").items():
            if isinstance(value, bool | int | float | str):
                out[f"{prefix}_{key}"] = int(value) if isinstance(value, bool) else value
    geom = rig_geometry(cfg)
    out.update(
        t_int_s=float(geom.t_int_s), line_period_s=float(geom.line_period_s),
        object_pixel_m=float(geom.object_pixel_m), delta_m=float(geom.delta_m),
        fusion_mu1=int(cfg.fusion.mu1), fusion_mu2=int(cfg.fusion.mu2),
    )
    return out


def pass_coords(cfg: BenchConfig, st: tuple[int, ...]) -> dict[str, Any]:
    """The coordinates of a pass: ``stage``, ``line``, ``column`` and :func:`physical_coords`."""
    coords: dict[str, Any] = {
        "stage": np.asarray(st, dtype=np.int64), "line": np.arange(cfg.lines),
        "column": np.arange(cfg.sensor.columns),
    }
    coords.update(physical_coords(cfg))
    return coords


def pass_attrs(
    cfg: BenchConfig, seed: int | np.random.SeedSequence | np.random.Generator, setup: RenderSetup, *,
    fused: bool,
) -> dict[str, Any]:
    """The attributes of a pass's dataset: the resolved config as TOML text and its SHA-256, the
    seed, the version, engine, variant, ``beta_bits``, pedestal [DN], ``t_int_s`` [s], frames, the
    sensor's chain (``sensor_chain``, ``truth_exact``), :func:`constant_attrs` and, when fused,
    ``mu1`` and ``mu2``."""
    attrs: dict[str, Any] = dict(
        title=f"bench_sim simulation of {cfg.name}",
        config=config_to_toml_text(cfg),
        config_sha256=config_sha256(cfg),
        seed=int(seed) if isinstance(seed, int | np.integer) else -1,
        version=__version__,
        engine=str(setup.info["engine"]),
        variant=str(setup.info["variant"]),
        beta_bits=int(cfg.dtdi.beta_bits),
        pedestal_dn=pedestal_dn(cfg),
        t_int_s=float(setup.geom.t_int_s),
        frames=int(setup.frames),
    )
    attrs.update(sensor_chain(cfg.sensor).attrs())  # sensor_chain, truth_exact (truth_not_exact)
    if isinstance(seed, np.random.SeedSequence):
        attrs.update(seed_entropy=str(seed.entropy), seed_spawn_key=str(list(seed.spawn_key)))
    attrs.update(constant_attrs(cfg))
    if fused:
        attrs.update(mu1=int(cfg.fusion.mu1), mu2=int(cfg.fusion.mu2))
    return attrs


def store_chunks(dims: tuple[str, ...], shape: tuple[int, ...]) -> tuple[int, ...]:
    """The chunk shape of a stored variable of ``dims`` and ``shape``: 1 along ``sample`` and
    ``stage``, every column, lines in blocks of ``max(1, CHUNK_PIXELS // columns)``."""
    size = dict(zip(dims, shape, strict=True))
    block = max(1, min(size.get("line", 1), CHUNK_PIXELS // max(size.get("column", 1), 1)))
    return tuple(block if d == "line" else size[d] if d == "column" else 1 for d in dims)


def stored_dataset(ds: xr.Dataset, beta_bits: int) -> xr.Dataset:
    """A pass's dataset in the stored schema: every variable of
    :data:`bench_sim.pipeline.PASS_VARIABLES` cast to its stored dtype, with the chunks of
    :func:`store_chunks` as its encoding (other variables, e.g. the e-SFR, as they are)."""
    out = ds.copy()
    for name in out.data_vars:
        var = VARIABLES_BY_NAME.get(str(name))
        if var is None:
            continue
        arr = out[name]
        out[name] = arr.astype(var.stored_dtype(beta_bits))
        out[name].attrs = dict(arr.attrs)
        out[name].encoding = {"chunks": store_chunks(tuple(str(d) for d in arr.dims), arr.shape)}
    return out
