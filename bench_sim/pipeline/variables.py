"""The variables of a pass: their table (names, dimensions, dtypes, units, stored dtypes), the
dtypes a pass allocates, and the attributes each variable carries (the coordinates and the
dataset's attributes: :mod:`bench_sim.pipeline.store_schema`).

:data:`PASS_VARIABLES` is the one table of the pass's variables: the arrays
:func:`bench_sim.pipeline.run_pass` allocates, the dataset's variables and units, the data set's
stored dtypes (:mod:`bench_sim.workflows.dataset.reader`) and the resource estimates
(:func:`stage_pixel_bytes`) all follow it.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from bench_sim.config import BETA_BITS_MAX, BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.sensor.model import word_dtype

__all__ = [
    "Variable", "PASS_VARIABLES", "VARIABLES_BY_NAME", "STAGE_DIMS", "IMAGE_DIMS", "WORD", "pass_variables",
    "stage_pixel_bytes", "pass_dtypes", "check_variables", "IMAGE_TRUTH_INPUTS", "variable_attrs",
    "pedestal_dn",
]

# --- the pass's variables ------------------------------------------------------------------------

#: dimensions of a variable per stage, and of a fused image
STAGE_DIMS = ("stage", "line", "column")
IMAGE_DIMS = ("line", "column")
#: dtype of the stage word: :func:`bench_sim.sensor.model.word_dtype` of ``dtdi.beta_bits`` in a
#: pass, the widest word (``beta = 32``) where stored for any ``beta`` (a data set)
WORD = "word"
#: the stage truth (of both fusion stages) the image variables of the truth are made of
#: (:func:`bench_sim.pipeline.fused_images.fused_images`)
IMAGE_TRUTH_INPUTS = ("linear_dn", "mean_dn", "noise_std_dn", "photons")


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
        A map derived from the truth and the fused image (:func:`pass_variables` lists it only
        when asked; ``simulate`` and the data sets store it).
    pedestal
        Whether the values carry the words' pedestal: ``"yes"`` (the words and their
        expectations), ``"no"`` (removed: the fused images), ``""`` (not a level).
    """

    name: str
    dims: tuple[str, ...]
    dtype: str
    units: str
    doc: str
    truth: bool = False
    map: bool = False
    pedestal: str = ""

    def array_dtype(self, beta_bits: int) -> np.dtype:
        """The dtype of the array in a pass of ``beta_bits``-bit words."""
        return word_dtype(beta_bits) if self.dtype == WORD else np.dtype(self.dtype)

    def stored_dtype(self, beta_bits: int | None) -> np.dtype:
        """The dtype of the variable in a file (``simulate``'s and a data set's, the one schema):
        the word in the smallest unsigned type that holds ``2**beta - 1`` (``uint16`` at 12 bits;
        ``None``: the widest word, 32 bits), the truth's float64 as float32 (its relative
        precision 6e-8 is far below any noise it is compared with), the rest as in the pass."""
        if self.dtype == WORD:
            return np.dtype(np.min_scalar_type(2 ** (BETA_BITS_MAX if beta_bits is None else beta_bits) - 1))
        return np.dtype("float32") if self.dtype == "float64" else np.dtype(self.dtype)


#: The one table of the pass's variables, in dataset order.
PASS_VARIABLES: tuple[Variable, ...] = (
    Variable("dn", STAGE_DIMS, WORD, "DN", "DTDI stage word (paper eq. 1-2, 4)", pedestal="yes"),
    Variable("mean_dn", STAGE_DIMS, "float64", "DN",
             "exact expectation of the stage word (full-well, ADC and word clips included)", truth=True,
             pedestal="yes"),
    Variable("linear_dn", STAGE_DIMS, "float64", "DN",
             "expectation of the stage word in the linear model, before any clip", truth=True,
             pedestal="yes"),
    Variable("noise_std_dn", STAGE_DIMS, "float64", "DN",
             "temporal standard deviation of the stage word (EMVA 1288: every read's variance and the "
             "word's clip, exact for the sensor's chain)", truth=True),
    Variable("photons", STAGE_DIMS, "float64", "photons",
             "mean photons collected by the stage pixel (sum over its m rows)", truth=True),
    Variable("reflectance", STAGE_DIMS, "float32", "1",
             "target reflectance integrated by the stage pixel's footprints", truth=True),
    Variable("clipped", STAGE_DIMS, "bool", "1",
             "a read hit full well or the ADC top, or the word hit 2**beta - 1 (this draw)", truth=True),
    Variable("gamma_hdr", IMAGE_DIMS, "float32", "DN",
             "Gamma_HDR, paper eq. 11 of the stage words, in stage-mu2 units, offsets (pedestal and "
             "accumulated black offset) removed", pedestal="no"),
    Variable("gamma_hdr_source", IMAGE_DIMS, "int16", "1", "stage each Gamma_HDR pixel came from"),
    Variable("true_hdr_dn", IMAGE_DIMS, "float32", "DN",
             "the true HDR target: the noise-free stage-mu2 signal without any clip (linear_dn of stage "
             "mu2 less its offsets), stage-mu2 units", truth=True, pedestal="no"),
    Variable("eq11_expected_dn", IMAGE_DIMS, "float32", "DN",
             "eq. 11 of the expected stage words (mean_dn of mu1, mu2 clipped to the word), offsets "
             "removed, stage-mu2 units: eq. 11 without noise, not the truth", truth=True, pedestal="no"),
    Variable("stage_clip_flags", IMAGE_DIMS, "uint8", "1",
             "bit 0: stage mu1, bit 1: stage mu2 not clear of its clips (a clip takes more from the "
             "stage's expectation than from a normal read 4 sigma below its clip)", truth=True),
    Variable("hdr_recoverable", IMAGE_DIMS, "bool", "1",
             "some fused stage is clear of its clips (stage_clip_flags < 3): the true HDR target is "
             "recoverable from the stage words", truth=True),
    Variable("gamma_hdr_error", IMAGE_DIMS, "float32", "1",
             "relative error of Gamma_HDR against the true HDR target true_hdr_dn (nan below 1 DN)",
             truth=True, map=True),
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


def stage_pixel_bytes(beta_bits: int | None, *, truth: bool, stored: bool = False) -> int:
    """Bytes per stage pixel of the stage variables [bytes]: in a pass of ``beta_bits``-bit
    words (``None``: the widest), or as stored in a file (``stored``:
    :meth:`Variable.stored_dtype`)."""
    beta = BETA_BITS_MAX if beta_bits is None else beta_bits
    return sum((v.stored_dtype(beta) if stored else v.array_dtype(beta)).itemsize
               for v in pass_variables(STAGE_DIMS, truth=truth))


def pass_dtypes(
    cfg: BenchConfig, st: tuple[int, ...], *, truth: bool, truth_stages: tuple[int, ...] | None = None,
    variables: Collection[str] | None = None,
) -> tuple[dict[str, np.dtype], dict[str, np.dtype]]:
    """The dtypes of a pass's stage variables and of its image variables (``gamma_hdr`` and
    ``gamma_hdr_source`` when both fusion stages are in ``st``; the maps of the truth when
    both have it: in ``truth_stages``, default ``st``), from :data:`PASS_VARIABLES`; of those
    named in ``variables`` only (:func:`check_variables`; default: all)."""
    beta = cfg.dtdi.beta_bits
    stage = {v.name: v.array_dtype(beta) for v in pass_variables(STAGE_DIMS, truth=truth)}
    both = {cfg.fusion.mu1, cfg.fusion.mu2}
    maps = truth and both <= set(st if truth_stages is None else truth_stages)
    image = {v.name: v.array_dtype(beta) for v in pass_variables(IMAGE_DIMS, truth=maps, maps=True)}
    image = image if both <= set(st) else {}
    if variables is None:
        return stage, image
    keep = set(check_variables(variables))
    return ({n: dt for n, dt in stage.items() if n in keep}, {n: dt for n, dt in image.items() if n in keep})


def check_variables(variables: Collection[str]) -> tuple[str, ...]:
    """``variables`` (names of :data:`PASS_VARIABLES` a pass keeps) in table order, ``dn``
    always among them; :class:`BenchSimError` (one line) for an unknown name, or for a map of
    the truth without the stage truth it is made of (:data:`IMAGE_TRUTH_INPUTS`)."""
    names = set(variables) | {"dn"}
    if unknown := sorted(names - set(VARIABLES_BY_NAME)):
        raise BenchSimError(f"variables: unknown {unknown}; allowed {[v.name for v in PASS_VARIABLES]}")
    maps = sorted(n for n in names if VARIABLES_BY_NAME[n].truth and VARIABLES_BY_NAME[n].dims == IMAGE_DIMS)
    if maps and (missing := [n for n in IMAGE_TRUTH_INPUTS if n not in names]):
        raise BenchSimError(f"variables: {maps} are made of the stage truth {list(IMAGE_TRUTH_INPUTS)}; "
                            f"add {missing}")
    return tuple(v.name for v in PASS_VARIABLES if v.name in names)


def variable_attrs(cfg: BenchConfig, name: str) -> dict[str, Any]:
    """``units`` and ``long_name`` of a pass variable, ``pedestal_included`` (``"yes"``,
    ``"no"`` or ``"not applicable"``) with the pedestal ``pedestal_dn`` [DN] where it applies; a
    truth variable also says whether it is exact for the sensor's chain (``truth_exact``: 1 or 0,
    and ``truth_not_exact``: why not)."""
    var = VARIABLES_BY_NAME[name]
    attrs: dict[str, Any] = {"units": var.units, "long_name": var.doc,
                             "pedestal_included": var.pedestal or "not applicable"}
    if var.pedestal:
        attrs["pedestal_dn"] = pedestal_dn(cfg)
    if var.truth:
        chain = sensor_chain(cfg.sensor)
        attrs["truth_exact"] = int(not chain.not_exact)
        if chain.not_exact:
            attrs["truth_not_exact"] = "; ".join(chain.not_exact)
    return attrs


def pedestal_dn(cfg: BenchConfig) -> float:
    """The pedestal [DN] every stage word of ``cfg`` carries (``dtdi.pedestal_dn``)."""
    return float(getattr(cfg.dtdi, "pedestal_dn", 0.0))
