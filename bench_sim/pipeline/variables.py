"""The variables of a pass: their table (names, dimensions, dtypes, units), the dtypes a pass
allocates, and the coordinates and attributes its dataset carries.

:data:`PASS_VARIABLES` is the one table of the pass's variables: the arrays
:func:`bench_sim.pipeline.run_pass` allocates, the dataset's variables and units, the data set's
stored dtypes (:mod:`bench_sim.workflows.dataset.reader`) and the resource estimates
(:func:`stage_pixel_bytes`) all follow it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BETA_BITS_MAX, BenchConfig, config_sha256, config_to_toml_text
from bench_sim.render.exposures import RenderSetup
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.model import word_dtype
from bench_sim.version import __version__

__all__ = [
    "Variable", "PASS_VARIABLES", "VARIABLES_BY_NAME", "STAGE_DIMS", "IMAGE_DIMS", "WORD", "pass_variables",
    "stage_pixel_bytes", "pass_dtypes", "pass_coords", "pass_attrs", "COORD_ATTRS", "variable_attrs",
    "pedestal_dn",
]

# --- the pass's variables ------------------------------------------------------------------------

#: dimensions of a variable per stage, and of a fused image
STAGE_DIMS = ("stage", "line", "column")
IMAGE_DIMS = ("line", "column")
#: dtype of the stage word: :func:`bench_sim.sensor.model.word_dtype` of ``dtdi.beta_bits`` in a
#: pass, the widest word (``beta = 32``) where stored for any ``beta`` (a data set)
WORD = "word"


@dataclass(frozen=True)
class Variable:
    """One variable of a pass.

    Attributes
    ----------
    name
        Variable name in the dataset and the files.
    dims
        :data:`STAGE_DIMS` or :data:`IMAGE_DIMS`.
    dtype
        numpy dtype name, or :data:`WORD` (the stage word, its width set by ``beta``).
    units
        Units (``"1"``: dimensionless).
    doc
        Long name (the dataset's ``long_name`` attribute).
    truth
        Computed only with the truth (``run_pass(..., truth=True)``).
    map
        A map of ``simulate`` derived from the truth and the fused image (not a data set's
        variable: :func:`pass_variables` lists it only when asked).
    """

    name: str
    dims: tuple[str, ...]
    dtype: str
    units: str
    doc: str
    truth: bool = False
    map: bool = False

    def array_dtype(self, beta_bits: int) -> np.dtype:
        """The dtype of the array in a pass of ``beta_bits``-bit words."""
        return word_dtype(beta_bits) if self.dtype == WORD else np.dtype(self.dtype)

    @property
    def stored_dtype(self) -> str:
        """The dtype name that holds the variable for any ``beta`` (a data set's arrays)."""
        return self.array_dtype(BETA_BITS_MAX).name


#: The one table of the pass's variables, in dataset order.
PASS_VARIABLES: tuple[Variable, ...] = (
    Variable("dn", STAGE_DIMS, WORD, "DN", "DTDI stage word (paper eq. 1-2, 4)"),
    Variable("mean_dn", STAGE_DIMS, "float64", "DN",
             "exact expectation of the stage word (full-well, ADC and word clips included)", truth=True),
    Variable("linear_dn", STAGE_DIMS, "float64", "DN",
             "expectation of the stage word in the linear model, before any clip", truth=True),
    Variable("noise_std_dn", STAGE_DIMS, "float64", "DN",
             "temporal standard deviation of the stage word (EMVA 1288: every read's variance and the "
             "word's clip, exact for the sensor's chain)", truth=True),
    Variable("photons", STAGE_DIMS, "float64", "photons",
             "mean photons collected by the stage pixel (sum over its m rows)", truth=True),
    Variable("reflectance", STAGE_DIMS, "float32", "1",
             "target reflectance integrated by the stage pixel's footprints", truth=True),
    Variable("clipped", STAGE_DIMS, "bool", "1",
             "a read hit full well or the ADC top, or the word hit 2**beta - 1", truth=True),
    Variable("gamma_hdr", IMAGE_DIMS, "float32", "DN",
             "Gamma_HDR, paper eq. 11, in stage-mu2 units, pedestal removed"),
    Variable("gamma_hdr_source", IMAGE_DIMS, "int16", "1", "stage each Gamma_HDR pixel came from"),
    Variable("gamma_hdr_error", IMAGE_DIMS, "float32", "1",
             "relative error of Gamma_HDR against its exact expectation (linear_dn of stage mu2 less "
             "the pedestal; nan below 1 DN)", truth=True, map=True),
    Variable("tdi_light_ratio", IMAGE_DIMS, "float32", "1",
             "TDI-window light ratio r = (photons_mu2 / mu2) / (photons_mu1 / mu1); eq. 11 assumes 1",
             truth=True, map=True),
)
#: name -> its :class:`Variable` of :data:`PASS_VARIABLES`
VARIABLES_BY_NAME: dict[str, Variable] = {v.name: v for v in PASS_VARIABLES}


def pass_variables(
    dims: tuple[str, ...] | None = None, *, truth: bool = True, maps: bool = False
) -> tuple[Variable, ...]:
    """The variables of :data:`PASS_VARIABLES` with dimensions ``dims`` (default: all), without
    the truth when ``truth`` is false, with ``simulate``'s maps (``gamma_hdr_error``,
    ``tdi_light_ratio``) only when ``maps``."""
    return tuple(v for v in PASS_VARIABLES if (dims is None or v.dims == dims) and (truth or not v.truth)
                 and (maps or not v.map))


def stage_pixel_bytes(beta_bits: int | None, *, truth: bool) -> int:
    """Bytes per stage pixel of the stage variables [bytes]: in a pass of ``beta_bits``-bit
    words, or as stored for any ``beta`` (``None``)."""
    beta = BETA_BITS_MAX if beta_bits is None else beta_bits
    return sum(v.array_dtype(beta).itemsize for v in pass_variables(STAGE_DIMS, truth=truth))


def pass_dtypes(
    cfg: BenchConfig, st: tuple[int, ...], *, truth: bool, truth_stages: tuple[int, ...] | None = None
) -> tuple[dict[str, np.dtype], dict[str, np.dtype]]:
    """The dtypes of a pass's stage variables and of its image variables (``gamma_hdr`` and
    ``gamma_hdr_source`` when both fusion stages are in ``st``; the maps of the truth when
    both have it: in ``truth_stages``, default ``st``), from :data:`PASS_VARIABLES`."""
    beta = cfg.dtdi.beta_bits
    stage = {v.name: v.array_dtype(beta) for v in pass_variables(STAGE_DIMS, truth=truth)}
    both = {cfg.fusion.mu1, cfg.fusion.mu2}
    maps = truth and both <= set(st if truth_stages is None else truth_stages)
    image = {v.name: v.array_dtype(beta) for v in pass_variables(IMAGE_DIMS, truth=maps, maps=True)}
    return stage, (image if both <= set(st) else {})


def variable_attrs(cfg: BenchConfig, name: str) -> dict[str, Any]:
    """``units`` and ``long_name`` of a pass variable; a truth variable also says whether it is
    exact for the sensor's chain (``truth_exact``: 1 or 0, and ``truth_not_exact``: why not)."""
    var = VARIABLES_BY_NAME[name]
    attrs: dict[str, Any] = {"units": var.units, "long_name": var.doc}
    if var.truth:
        chain = sensor_chain(cfg.sensor)
        attrs["truth_exact"] = int(not chain.not_exact)
        if chain.not_exact:
            attrs["truth_not_exact"] = "; ".join(chain.not_exact)
    return attrs


#: units and long names of the pass's coordinates
COORD_ATTRS = {
    "line": {"units": "1", "long_name": "scene line (material at line * delta along the track)"},
    "column": {"units": "1", "long_name": "sensor column"},
    "stage": {"units": "1", "long_name": "DTDI stage m (rows summed)"},
}


def pass_coords(cfg: BenchConfig, st: tuple[int, ...]) -> dict[str, np.ndarray]:
    """The coordinates ``stage``, ``line``, ``column`` of a pass."""
    return {"stage": np.asarray(st, dtype=np.int64), "line": np.arange(cfg.lines),
            "column": np.arange(cfg.sensor.columns)}


def pass_attrs(
    cfg: BenchConfig, seed: int | np.random.SeedSequence | np.random.Generator, setup: RenderSetup, *,
    fused: bool,
) -> dict[str, Any]:
    """The attributes of a pass's dataset: the resolved config as TOML text and its SHA-256, the
    seed, the version, engine, variant, ``beta_bits``, pedestal [DN], ``t_int_s`` [s], frames and,
    when fused, ``mu1`` and ``mu2``."""
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
    if fused:
        attrs.update(mu1=int(cfg.fusion.mu1), mu2=int(cfg.fusion.mu2))
    return attrs




def pedestal_dn(cfg: BenchConfig) -> float:
    """The pedestal [DN] every stage word of ``cfg`` carries (``dtdi.pedestal_dn``)."""
    return float(getattr(cfg.dtdi, "pedestal_dn", 0.0))
