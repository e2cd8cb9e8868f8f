"""The twin ``calibrate`` writes: the ``[sensor]`` section of a camera from its fit (or its
published EMVA 1288 results), with the effects that make the twin follow the camera beyond
EMVA 1288's linear model, and the files they read.

From a fit (:func:`twin_from_fit`)
----------------------------------
``conversion_gain_dn_per_e = K``, ``quantum_efficiency = eta`` (kept from the base config and
reported unknown without a photon calibration); ``read_noise_e`` is the dark noise at zero
exposure (several exposure times) or ``sqrt(sigma_d^2 - I_d t)`` (one); the dark current is the
fitted one (several exposure times) or 0 (then the whole dark noise is read noise, exact at the
measured exposure time); ``black_offset_dn`` is the dark level less the dark signal (kept where
the table gave the signal only); ``adc_bits`` the camera's. Where the camera clips
(:func:`bench_sim.metrics.emva_fit.clip_kind`):

* on its pixel (``full_well``): ``full_well_e`` is the clip whose variance maximum lies at the
  measured saturation capacity (:func:`bench_sim.sensor.saturation.full_well_for_saturation`);
* on its ADC (``adc``): the ADC's top is the clip; the full well, not measurable, is set
  :data:`FULL_WELL_ABOVE_ADC` above the charge that reaches it;
* on both: the full well at the charge that reaches the ADC's top.

Effects (``[sensor.effects.<name>]``, :mod:`bench_sim.sensor.effects`):

* ``nonlinearity`` (``form = "table"``, ``response.csv``): the fitted response curve, where the
  camera is significantly non-linear;
* ``defects`` (``map_file = "defect_map.csv"``): the defect pixels found in the images that lie
  on the twin's sensor (all of them are in ``defects.csv``);
* ``offset_pattern``: the pixel part of the offset pattern at 0 s (a dark series), where it is
  significant (3 standard errors); its column part as ``column_offset_dn``; ``dsnu_e_s`` the dark
  current's non-uniformity;
* ``row_noise``: the temporal row noise, where it is significant (3 standard errors).

References
----------
EMVA Standard 1288, Release 4.0 Linear (2021).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.metrics.emva_fit import CameraFit
from bench_sim.metrics.frame_series import FrameAnalysis
from bench_sim.sensor.saturation import full_well_for_saturation
from bench_sim.workflows.calibrate_inputs import CalibrationInput

__all__ = ["Twin", "twin_from_fit", "twin_from_results", "FULL_WELL_ABOVE_ADC", "RESPONSE_FILE", "MAP_FILE"]

#: Where the ADC clips first, the twin's full well lies this much above the charge that reaches
#: the ADC's top (not measurable; any value above keeps the ADC the clip)
FULL_WELL_ABOVE_ADC = 1.25
#: Standard errors from 0 at which an offset pattern or a row noise is carried into the twin
SIGNIFICANT = 3.0
#: The twin's files
RESPONSE_FILE, MAP_FILE, DEFECTS_FILE = "response.csv", "defect_map.csv", "defects.csv"
#: Points of the response table
_RESPONSE_POINTS = 257


@dataclass
class Twin:
    """The twin of a camera: ``sensor`` (the ``[sensor]`` keys, effects under ``effects``),
    ``kept`` (keys kept from the base config), ``unknown`` (quantities the input does not give:
    reported as unknown, not invented), ``files`` (name -> CSV text the effects read) and
    ``notes`` (sentences for the report)."""

    sensor: dict[str, Any]
    kept: list[str]
    unknown: list[str] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def add_effect(self, name: str, entry: dict[str, Any]) -> None:
        """Add ``[sensor.effects.<name>]``."""
        self.sensor.setdefault("effects", {})[name] = entry


def _adc_electrons(fit: CameraFit, black: float, dark_e: float) -> float:
    """Linear electrons whose read reaches the ADC's top: the response inverted at the top."""
    k, top = fit.k_dn_per_e, float((1 << fit.bits) - 1)
    target = top - black - k * dark_e  # the signal [DN] at the top
    resp = fit.response
    if resp is None or not fit.linearized:
        return target / k
    lo, hi = 0.0, 4.0 * target / resp.slope
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(resp(np.array([mid]))[0]) < target else (lo, mid)
    return resp.slope * 0.5 * (lo + hi) / k


def _clip(twin: Twin, fit: CameraFit, black: float, dark_e: float, bits_given: bool) -> None:
    """``full_well_e`` (and ``adc_bits``) so that the twin clips where the camera does."""
    e_adc = _adc_electrons(fit, black, dark_e)
    if fit.clips_on == "adc":
        twin.sensor["full_well_e"] = FULL_WELL_ABOVE_ADC * e_adc
        twin.notes.append(
            f"The camera clips on its ADC (plateau variance {fit.plateau_var_dn2:.3g} DN^2): the twin's "
            f"clip is the {fit.bits}-bit ADC's top; its full well, not measurable, is set "
            f"{FULL_WELL_ABOVE_ADC - 1:.0%} above the {e_adc:.5g} e- that reach it."
        )
        return
    if fit.clips_on == "both":
        twin.sensor["full_well_e"] = e_adc
        twin.notes.append(
            f"The camera clips on its pixels and its ADC alike: the twin's full well is the "
            f"{e_adc:.5g} e- that reach the ADC's top."
        )
        return
    fw = full_well_for_saturation(fit.saturation_capacity_e, dark_e)
    twin.sensor["full_well_e"] = fw
    if fit.clips_on == "unknown":
        twin.notes.append(
            "The table ends at the variance maximum: where the camera clips is not known; the "
            "saturation capacity is a lower bound and so is the twin's full well."
        )
    elif fw > e_adc:
        if bits_given:
            twin.notes.append(
                f"Warning: the camera clips on its pixels but a full well of {fw:.5g} e- lies above "
                f"the {fit.bits}-bit ADC's top ({e_adc:.5g} e-): the twin clips on the ADC."
            )
        else:
            twin.sensor["adc_bits"] = int(min(16, math.ceil(math.log2(fit.k_dn_per_e * fw + black + 2.0))))


def _response_table(twin: Twin, fit: CameraFit) -> None:
    """The fitted response as ``response.csv`` (linear e- -> e-) and a ``nonlinearity`` effect."""
    resp = fit.response
    if resp is None or not fit.linearized:
        return
    fw = float(twin.sensor["full_well_e"])
    e = np.linspace(0.0, fw, _RESPONSE_POINTS)
    r = resp.electrons_response(e, fit.k_dn_per_e)
    twin.files[RESPONSE_FILE] = "input_e,output_e\n" + "".join(
        f"{a:.6f},{b:.6f}\n" for a, b in zip(e, r, strict=True)
    )
    twin.add_effect(
        "nonlinearity", {"kind": "nonlinearity", "form": "table", "table": RESPONSE_FILE, "domain": "e"}
    )
    twin.notes.append(
        f"The camera's response is non-linear (LE {fit.linearity_error_percent:.3g} %; a degree-"
        f"{resp.degree} response fits it to {resp.rms_relative:.2g} rms): the twin carries it as "
        f"`{RESPONSE_FILE}` (sensor.effects.nonlinearity), and K was fitted to the linearised photon "
        f"transfer."
    )


def _from_frames(twin: Twin, an: FrameAnalysis, base: BenchConfig, t_exp: float) -> None:
    """Non-uniformities, defects and row noise of an image input."""
    s, k = twin.sensor, an.fit.k_dn_per_e
    s["prnu"] = an.spatial["prnu"]["total"]
    split = an.dsnu_split
    if split is not None:
        s["dsnu_e_s"] = split["dark_current_nu_e_s"]["total_e_s"]
        s["column_offset_dn"] = split["dsnu0_e"]["column_e"] * k
        d0 = split["dsnu0_e"]
        if d0["pixel_e"] > SIGNIFICANT * d0["pixel_se_e"]:  # a pattern the data show
            twin.add_effect(
                "offset_pattern", {"kind": "offset_pattern", "rms_e": split["dsnu0_e"]["pixel_e"]}
            )
    else:
        s["dsnu_e_s"] = an.spatial["dsnu_e"]["total_e"] / max(an.spatial["exposure_s"] or t_exp, 1e-300)
        s["column_offset_dn"] = 0.0
    rows = an.defects.rows()
    if rows:
        inside = [r for r in rows if r[0] < base.sensor.rows and r[1] < base.sensor.columns]
        twin.files[DEFECTS_FILE] = "row,column,kind,value\n" + "".join(
            f"{a},{b},{c},{d:.6g}\n" for a, b, c, d in rows
        )
        if inside:
            twin.files[MAP_FILE] = "row,column,kind,value\n" + "".join(
                f"{a},{b},{c},{d:.6g}\n" for a, b, c, d in inside
            )
            twin.add_effect("defects", {"kind": "defects", "map_file": MAP_FILE})
        twin.notes.append(
            f"{len(rows)} defect pixels "
            f"({', '.join(f'{v} {n}' for n, v in an.defects.counts().items() if v)}) "
            f"in `{DEFECTS_FILE}`; the {len(inside)} on the twin's {base.sensor.rows} x "
            f"{base.sensor.columns} "
            f"sensor are its `{MAP_FILE}` (sensor.effects.defects)."
        )
    rn = an.row_noise
    if rn is not None and rn.var_dn2 > SIGNIFICANT * rn.var_se_dn2 and rn.var_dn2 > 0:
        twin.add_effect("row_noise", {"kind": "row_noise", "rms_dn": math.sqrt(rn.var_dn2)})


def twin_from_fit(
    inp: CalibrationInput, fit: CameraFit, base: BenchConfig, frames: FrameAnalysis | None = None
) -> Twin:
    """The twin of a fitted table or image series (module docstring)."""
    tab = inp.table if frames is None else frames.table
    assert tab is not None
    multi = tab.dark_exposure_s.size >= 3
    idark = fit.dark_current_e_s if multi and fit.dark_current_e_s > 0 else 0.0
    t = fit.exposure_s
    twin = Twin(
        sensor={
            "conversion_gain_dn_per_e": fit.k_dn_per_e,
            "read_noise_e": fit.dark_noise_e,
            "dark_current_e_s": idark,
            "adc_bits": fit.bits,
        },
        kept=[],
    )
    black = base.sensor.black_offset_dn
    if fit.dark_offset_known:
        black = max(fit.dark_offset_dn - (0.0 if multi else fit.k_dn_per_e * idark * t), 0.0)
        twin.sensor["black_offset_dn"] = black
    else:
        twin.kept.append("black_offset_dn")
        twin.unknown.append("dark offset (the table gave the dark-subtracted signal only)")
    if fit.qe_known:
        twin.sensor["quantum_efficiency"] = fit.quantum_efficiency
    else:
        twin.kept.append("quantum_efficiency")
        twin.unknown += ["quantum efficiency", "responsivity"]
    _clip(twin, fit, black, idark * t, tab.bits is not None)
    _response_table(twin, fit)
    if tab.wavelength_nm is not None:
        twin.sensor["wavelength_m"] = tab.wavelength_nm * 1e-9
    else:
        twin.kept.append("wavelength_m")
    if frames is not None:
        _from_frames(twin, frames, base, t)
    elif inp.spatial and inp.spatial.get("exposure_s", t) > 0:
        twin.sensor.update(
            dsnu_e_s=inp.spatial["dsnu_dn"] / fit.k_dn_per_e / inp.spatial.get("exposure_s", t),
            prnu=inp.spatial["prnu"],
            column_offset_dn=0.0,
        )
    else:
        twin.kept += ["dsnu_e_s", "prnu", "column_offset_dn"]
    _check_qe(inp, twin)
    return twin


def twin_from_results(inp: CalibrationInput, base: BenchConfig) -> Twin:
    """The twin of published EMVA 1288 results, taken as they are (a linear camera)."""
    r = inp.results
    t = r.get("exposure_s", base.timing.t_int_s)
    idark = r.get("dark_current_e_per_s", 0.0)
    k = r["K_dn_per_e"]
    fw = full_well_for_saturation(r["saturation_capacity_e"], idark * t)
    black = base.sensor.black_offset_dn
    bits = int(r["bits"]) if "bits" in r else max(8, math.ceil(math.log2(k * fw + black + 2.0)))
    twin = Twin(
        sensor={
            "conversion_gain_dn_per_e": k,
            "read_noise_e": math.sqrt(max(r["dark_noise_e"] ** 2 - idark * t, 0.0)),
            "dark_current_e_s": idark,
            "full_well_e": fw,
            "adc_bits": bits,
        },
        kept=["black_offset_dn"],
    )
    for key, src, scale in (("quantum_efficiency", "qe", 1.0), ("prnu", "prnu_percent", 0.01)):
        if src in r:
            twin.sensor[key] = r[src] * scale
        else:
            twin.kept.append(key)
    if "qe" not in r:
        twin.unknown.append("quantum efficiency")
    if "wavelength_nm" in r:
        twin.sensor["wavelength_m"] = r["wavelength_nm"] * 1e-9
    else:
        twin.kept.append("wavelength_m")
    if "dsnu_e" in r and t > 0:
        twin.sensor.update(dsnu_e_s=r["dsnu_e"] / t, column_offset_dn=0.0)
    else:
        twin.kept += ["dsnu_e_s", "column_offset_dn"]
    _check_qe(inp, twin)
    return twin


def _check_qe(inp: CalibrationInput, twin: Twin) -> None:
    qe = twin.sensor.get("quantum_efficiency")
    if qe is not None and not 0 < qe <= 1:
        raise BenchSimError(
            f"{inp.path}: fitted quantum efficiency {qe:.4g} outside 0..1: check photons_per_pixel (mean "
            "photons per pixel during the exposure); without a photon calibration leave the column out "
            "(or give relative_irradiance): QE is then reported as unknown"
        )
