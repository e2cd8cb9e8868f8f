"""Fuse two stage images from files: ``bench-sim fuse``, by the paper's rule (eq. 11) or the
clip-aware rule (``--method``, :data:`bench_sim.fusion.methods.FUSE_METHODS`).

Inputs: two single-channel stage images of the same shape, 16-bit (or 8-bit) TIFF/PNG, EXR or
NPY (read by :func:`bench_sim.io.read_image`). They must hold **integer** DN values in
``0 .. 2**beta - 1``: a stage image is the sum of integer pixel reads, clipped to the ``beta``-bit
output word (paper eq. 1-4); a fractional value means the file is not a stage image in DN (for
example a 0..1 normalised EXR) and eq. 11's threshold would be meaningless, so it is refused.

Outputs, written only after every check has passed (the output folders writable, the images'
sizes read from their headers fitting in memory and on the disk), as one set: both files are
written under temporary names and renamed into place together, so a failure leaves neither:

* ``out`` (``.exr``): channel ``Y`` = ``Gamma_HDR`` [DN, stage-``mu2`` units, float32; exact for
  values below ``2**24``], channel ``source`` = the stage (``mu1`` or ``mu2``) each pixel came
  from; header attribute ``bench_sim`` (JSON): inputs (path, SHA-256, shape), the rule
  (``method``: ``eq11`` or ``clip``, and ``method_description``), ``mu1``, ``mu2``, ``beta``,
  ``Phi_FS``, the eq. 11 threshold, full scale, counts (among them
  ``pixels_from_clipped_high``: pixels taken from a ``Gamma2`` at its word's clip), units and
  the package version.
* ``tra`` (``.png``, optional): ``Gamma_TRA``, 8-bit, transform ``tra_method`` (default
  ``"log"``, see :mod:`bench_sim.fusion.tonemap`) over the HDR full scale
  ``(mu2/mu1) * (2**beta - 1)``; metadata in a text chunk.

Every problem raises :class:`~bench_sim.errors.BenchSimError` with one line naming the file or
option, the value and what is allowed.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from bench_sim.errors import BenchSimError
from bench_sim.fusion.common import FusionResult
from bench_sim.fusion.methods import FUSE_METHODS, check_fuse_method, fuse_pair
from bench_sim.fusion.paper import eq11_threshold_dn
from bench_sim.fusion.tonemap import TONEMAP_METHODS, gamma_tra
from bench_sim.io import (
    check_image_file,
    check_output_file,
    image_shape,
    output_files,
    read_image,
    sha256_file,
    write_exr,
    write_png,
)
from bench_sim.runtime.resources import check_resources
from bench_sim.sensor.model import check_beta_bits
from bench_sim.version import __version__
from bench_sim.workflows.estimates import estimate_fuse
from bench_sim.workflows.pedestal import default_pedestal_dn

__all__ = ["fuse_files", "check_stage_image"]


def _where(arr: np.ndarray, mask: np.ndarray) -> tuple[float, str]:
    idx = tuple(int(i) for i in np.argwhere(mask)[0])
    return float(arr[idx]), f"(row {idx[0]}, column {idx[1]})"


def check_stage_image(arr: np.ndarray, name: str, beta: int) -> None:
    """Refuse a stage image that is empty, non-finite, fractional or outside ``0 .. 2**beta - 1``.

    Parameters
    ----------
    arr
        2-D image [DN] as read by :func:`bench_sim.io.read_image`.
    name
        How to name it in the message (the file).
    beta
        Output word length [bits].
    """
    top = 2**beta - 1
    allowed = f"allowed: integers 0..{top} (2**beta - 1 with --beta {beta})"
    if arr.size == 0:
        raise BenchSimError(f"{name}: empty image (shape {arr.shape})")
    finite = np.isfinite(arr)
    if not finite.all():
        v, at = _where(arr, ~finite)
        raise BenchSimError(f"{name}: value {v} at {at} is not a finite number; {allowed}")
    frac = arr != np.floor(arr)
    if frac.any():
        v, at = _where(arr, frac)
        raise BenchSimError(
            f"{name}: value {v:g} at {at} is not an integer; a stage image holds integer DN "
            f"(sums of pixel reads), not normalised values; {allowed}"
        )
    if arr.min() < 0:
        v, at = _where(arr, arr < 0)
        raise BenchSimError(f"{name}: value {v:g} at {at} is negative; {allowed}")
    if arr.max() > top:
        v, at = _where(arr, arr > top)
        raise BenchSimError(f"{name}: value {v:g} at {at} exceeds 2**beta - 1 = {top}; {allowed}")


def _check_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise BenchSimError(f"{name} = {value!r}: must be an integer")
    return int(value)


def _read_quietly(path: Path) -> np.ndarray:
    """:func:`read_image` with tifffile's logged warnings held back (a broken TIFF is reported
    by the one-line error; the logger would add a second line on stderr)."""
    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        return read_image(path)
    finally:
        log.setLevel(level)


def _check_options(
    beta: Any, mu1: Any, mu2: Any, tra_method: str, pedestal_dn: float
) -> tuple[int, int, int]:
    """``(beta, mu1, mu2)`` checked: integers, a valid word length, ``1 <= mu1 < mu2``; a known
    display transform and a pedestal below the word clip."""
    beta = check_beta_bits(_check_int("--beta", beta), "--beta")
    mu1 = _check_int("--mu1", mu1)
    mu2 = _check_int("--mu2", mu2)
    if mu1 < 1:
        raise BenchSimError(f"--mu1 = {mu1}: must be a DTDI stage >= 1")
    if mu1 >= mu2:
        raise BenchSimError(f"--mu1 = {mu1}, --mu2 = {mu2}: need mu1 < mu2 (1 <= mu1 < mu2)")
    if tra_method not in TONEMAP_METHODS:
        raise BenchSimError(f"tra method = {tra_method!r}: allowed {', '.join(TONEMAP_METHODS)}")
    if not (np.isfinite(pedestal_dn) and 0 <= pedestal_dn < 2**beta - 1):
        raise BenchSimError(
            f"--pedestal = {pedestal_dn!r}: must lie in 0..{2**beta - 1} DN (below the word clip)"
        )
    return beta, mu1, mu2


def _check_outputs(low_p: Path, high_p: Path, out_p: Path, tra_p: Path | None) -> None:
    """The output files writable, of the right kinds, and none of them an input or each other."""
    check_output_file(out_p, "--out", ".exr", inputs=(low_p, high_p))
    if tra_p is not None:
        check_output_file(tra_p, "--tra", ".png", inputs=(low_p, high_p))
        if tra_p.resolve() == out_p.resolve():
            raise BenchSimError(f"--tra = {tra_p}: same file as --out")


def _read_stages(low_p: Path, high_p: Path, mu1: int, mu2: int, beta: int) -> tuple[np.ndarray, np.ndarray]:
    """The two stage images [DN], each checked (:func:`check_stage_image`), of one shape."""
    g1 = _read_quietly(low_p)
    g2 = _read_quietly(high_p)
    check_stage_image(g1, f"{low_p} (LOW, stage mu1 = {mu1})", beta)
    check_stage_image(g2, f"{high_p} (HIGH, stage mu2 = {mu2})", beta)
    if g1.shape != g2.shape:
        raise BenchSimError(
            f"{high_p}: shape {g2.shape} differs from {low_p} shape {g1.shape}; the two stage "
            "images must be the same size"
        )
    return g1, g2


def _hdr_meta(
    inputs: dict[str, tuple[Path, np.ndarray]],
    result: FusionResult,
    mu1: int,
    mu2: int,
    beta: int,
    pedestal_dn: float,
    method: str,
) -> dict[str, Any]:
    """The ``bench_sim`` attribute of the HDR EXR: inputs (path, SHA-256, shape), the rule,
    stages, word, eq. 11 threshold, full scale, counts, units and the package version."""
    g2 = inputs["high"][1]
    return {
        "kind": "Gamma_HDR",
        "method": method,
        "method_description": FUSE_METHODS[method],
        "version": __version__,
        "inputs": {
            k: {"path": str(p), "sha256": sha256_file(p), "shape": list(g.shape)}
            for k, (p, g) in inputs.items()
        },
        "mu1": mu1,
        "mu2": mu2,
        "beta": beta,
        "phi_fs_dn": 2**beta,
        "pedestal_dn": float(pedestal_dn),
        "threshold_dn": eq11_threshold_dn(mu1, mu2, beta, float(pedestal_dn)),
        "full_scale_dn": result.full_scale_dn,
        "units": f"DN in stage-mu2 (= {mu2}) units",
        "channels": {
            "Y": "Gamma_HDR [DN, stage-mu2 units]",
            "source": f"stage the pixel came from: {mu2} = gamma2 (eq. 10), {mu1} = (mu2/mu1)*gamma1 (eq. 8)",
        },
        "pixels_from_low": int(np.count_nonzero(result.source == mu1)),
        "pixels_saturated": int(np.count_nonzero(result.saturated)),
        "pixels_from_clipped_high": int(
            np.count_nonzero((result.source == mu2) & (g2 >= 2**beta - 1))
        ),
    }


def _write_outputs(
    out_p: Path,
    tra_p: Path | None,
    result: FusionResult,
    meta: dict[str, Any],
    tra_method: str,
    display: np.ndarray | None,
) -> None:
    """Write the HDR EXR and, with ``tra_p``, the ``Gamma_TRA`` PNG: both files or neither."""
    dests = [out_p] if tra_p is None else [out_p, tra_p]
    with output_files(dests) as tmps:  # both files or neither
        write_exr(tmps[0], {"Y": result.hdr, "source": result.source.astype(np.float32)}, meta)
        if tra_p is not None and display is not None:
            tra_meta = {
                "kind": "Gamma_TRA",
                "tra": tra_method,
                "formula": TONEMAP_METHODS[tra_method].formula,
                "x": "Gamma_HDR [DN]",
                "X_full_scale_dn": result.full_scale_dn,
                "bits": 8,
                "hdr": str(out_p),
                "method": meta["method"],
                "mu1": meta["mu1"],
                "mu2": meta["mu2"],
                "beta": meta["beta"],
                "version": __version__,
            }
            write_png(tmps[1], display, tra_meta)


def fuse_files(
    low: str | os.PathLike[str],
    high: str | os.PathLike[str],
    *,
    mu1: int,
    mu2: int,
    beta: int,
    out: str | os.PathLike[str],
    tra: str | os.PathLike[str] | None = None,
    tra_method: str = "log",
    pedestal_dn: float | None = None,
    method: str = "eq11",
) -> dict[str, Any]:
    """Read two stage images, fuse them (eq. 11 or the clip-aware rule), write the HDR EXR (and
    the ``Gamma_TRA`` PNG).

    Parameters
    ----------
    low
        Stage-``mu1`` image file (``Gamma1``).
    high
        Stage-``mu2`` image file (``Gamma2``), same shape.
    mu1, mu2
        Stages, ``1 <= mu1 < mu2``.
    beta
        Output word length of the inputs [bits], ``1 .. 32``; ``Phi_FS = 2**beta`` (eq. 4).
    out
        HDR output, ``.exr``.
    tra
        Optional display output, ``.png`` (8-bit).
    tra_method
        Display transform, one of ``log, gamma, histeq, reinhard, drago, mantiuk``.
    pedestal_dn
        Offset [DN] both stage words carry besides the signal (``--pedestal``): the DTDI
        pedestal, ``dtdi.pedestal_dn`` for images made by bench_sim (64 DN by default; their
        metadata names it); ``0`` for a plain word. It is subtracted before eq. 11. ``None``
        (the default): the ``dtdi.pedestal_dn`` the inputs' bench_sim metadata name, else 0
        (:func:`bench_sim.workflows.pedestal.default_pedestal_dn`); the returned
        ``pedestal_source`` says which.
    method
        Fusion rule, one of :data:`~bench_sim.fusion.methods.FUSE_METHODS`: ``"eq11"`` (the
        paper's, default) or ``"clip"`` (the highest stage whose word is below its clip).

    Returns
    -------
    dict
        The metadata written to the EXR header plus the output paths.

    Raises
    ------
    BenchSimError
        Any bad option or input (one line); nothing is written then.
    """
    method = check_fuse_method(method, "--method")  # before any work
    low_p, high_p, out_p = Path(low), Path(high), Path(out)
    tra_p = Path(tra) if tra is not None else None
    for p in (low_p, high_p):  # each input checked (kind, type, size in its header) before
        check_image_file(p)  # anything opens it: the pedestal's provenance reads its metadata
    if pedestal_dn is None:
        pedestal_dn, pedestal_source = default_pedestal_dn(low_p, high_p)
    else:
        pedestal_source = f"{pedestal_dn:g} DN (--pedestal)"
    beta, mu1, mu2 = _check_options(beta, mu1, mu2, tra_method, pedestal_dn)
    _check_outputs(low_p, high_p, out_p, tra_p)
    # sizes from the headers, before decoding anything
    shapes = {p: image_shape(p) for p in (low_p, high_p)}
    check_resources(estimate_fuse(max(shapes.values(), key=math.prod), tra_p is not None), out_p.parent)

    g1, g2 = _read_stages(low_p, high_p, mu1, mu2, beta)
    result = fuse_pair(g1, g2, method=method, mu1=mu1, mu2=mu2, beta=beta, pedestal_dn=float(pedestal_dn))
    display = gamma_tra(result.hdr, tra_method, full_scale_dn=result.full_scale_dn) if tra_p else None
    meta = _hdr_meta(
        {"low": (low_p, g1), "high": (high_p, g2)}, result, mu1, mu2, beta, pedestal_dn, method
    )
    meta["pedestal_source"] = pedestal_source
    _write_outputs(out_p, tra_p, result, meta, tra_method, display)
    return {**meta, "out": str(out_p), "tra": str(tra_p) if tra_p else None}
