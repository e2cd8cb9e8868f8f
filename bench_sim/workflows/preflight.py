"""The up-front checks every command makes before it computes anything.

In this order (cheap first): the output folder can receive an output set
(:func:`bench_sim.io.check_output_dir`), the run fits in the memory and on the disk available
(:func:`bench_sim.runtime.resources.check_resources` with the command's estimate,
:mod:`bench_sim.workflows.estimates`), the target image
file reads (``target.layout = "image"``), the measured spectra and the lens' files read and cover
what they must (:func:`bench_sim.rig.spectra.check_spectra`,
:func:`bench_sim.rig.lens_psf.lens_otf`), and the rendering backend chosen or forced can run
(:func:`bench_sim.runtime.backend.select_backend`). Each failure is one
:class:`~bench_sim.errors.BenchSimError` line; nothing has been written then. A run that renders
is warned (:class:`~bench_sim.errors.ConfigWarning`) when its system's MTF50 across the track
lies above Nyquist (:func:`nyquist_warning`).

A new command calls :func:`preflight` with its config, its output folder and its
:class:`~bench_sim.runtime.resources.ResourceEstimate`, then computes, then writes inside
:func:`bench_sim.io.output_set`. Commands that run many simulation tasks on the execution layer
(sweeps, data sets) call :func:`preflight_tasks` with every task's config and stages.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, overload

import numpy as np
from pydantic import BeforeValidator

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError, ConfigWarning
from bench_sim.fusion.tonemap import check_tonemap_method
from bench_sim.io import check_output_dir
from bench_sim.metrics.sfr_readings import mtf50
from bench_sim.rig.lens_psf import lens_otf, system_mtf_across
from bench_sim.rig.spectra import check_spectra
from bench_sim.rig.target_sources import check_target_image
from bench_sim.runtime.backend import select_backend
from bench_sim.runtime.resources import ResourceEstimate, check_resources, local_concurrency
from bench_sim.sensor.effects.chain import sensor_chain
from bench_sim.workflows.estimates import estimate_simulate, estimate_tasks

__all__ = ["preflight", "preflight_tasks", "nyquist_warning", "check_seed", "is_seed", "SeedField",
           "SEED_MAX", "SEED_RULE"]

#: The largest root seed: seeds are stored as signed 64-bit integers (Zarr, NetCDF attributes).
SEED_MAX = 2**63 - 1


#: What a root seed may be, for messages
SEED_RULE = "an integer in 0..2**63-1"


def is_seed(seed: object) -> bool:
    """Whether ``seed`` is a valid root seed: an integer (not a bool) in ``0 .. 2**63 - 1``.
    The one rule of every seed: ``--seed``, a sweep or dataset spec's ``seed``."""
    return not isinstance(seed, bool) and isinstance(seed, int | np.integer) and 0 <= int(seed) <= SEED_MAX


def _seed_value(value: Any) -> Any:
    if not is_seed(value):
        raise ValueError(f"must be {SEED_RULE}")
    return value


#: A spec file's root seed as a pydantic field type: :func:`is_seed` on the value as written
SeedField = Annotated[int, BeforeValidator(_seed_value)]


def check_seed(seed: object, what: str = "--seed") -> int:
    """A root seed (:func:`is_seed`). Raises :class:`~bench_sim.errors.BenchSimError` naming
    ``what`` otherwise."""
    if not is_seed(seed):
        raise BenchSimError(f"{what} = {seed!r}: must be {SEED_RULE}")
    return int(seed)  # type: ignore[call-overload]


@overload
def preflight(
    cfg: BenchConfig | None, *, out: str | os.PathLike[str], estimate: ResourceEstimate | None,
    render: bool = ..., what: str = ...,
) -> Path: ...
@overload
def preflight(
    cfg: BenchConfig | None, *, out: None, estimate: ResourceEstimate | None,
    render: bool = ..., what: str = ...,
) -> None: ...
def preflight(
    cfg: BenchConfig | None,
    *,
    out: str | os.PathLike[str] | None,
    estimate: ResourceEstimate | None,
    render: bool = True,
    what: str = "--out",
) -> Path | None:
    """Check a run before computing: output folder, memory and disk, target image, backend.

    Parameters
    ----------
    cfg
        The run's config (``None``: no config, e.g. ``fuse``).
    out
        Output folder of the run's output set (``None``: none, or checked by the caller).
    estimate
        What the run needs (``None``: no resource check).
    render
        Whether the run renders (the backend is chosen, or a forced one checked, up front).
    what
        Name of the output option, for messages.

    Returns
    -------
    Path or None
        ``out`` resolved.
    """
    if cfg is not None:  # config values, refused first as load_config's errors are
        check_tonemap_method(cfg.fusion.tra)
        sensor_chain(cfg.sensor)  # every effect's parameters, files and plug-ins
    out_path = check_output_dir(out, what) if out is not None else None
    if estimate is not None:
        check_resources(estimate, out_path)
    if cfg is not None:
        check_target_image(cfg.target)
        check_spectra(cfg)
        lens_otf(cfg)  # reads the lens' file, if any
        if render:
            select_backend(cfg.render.variant, "spectral" if cfg.render.spectral else "mono")
            line = nyquist_warning(cfg)
            if line:
                warnings.warn(line, ConfigWarning, stacklevel=2)
    return out_path


def nyquist_warning(cfg: BenchConfig) -> str | None:
    """The warning when the bench's system MTF50 across the track (the lens and the pixel
    aperture in closed form, :func:`bench_sim.rig.lens_psf.system_mtf_across`) lies above
    Nyquist (0.5 cycles/px): sharper than the lens can make it, the images alias; else ``None``."""
    f = np.linspace(0.0, 1.0, 2001)
    f50 = mtf50(f, system_mtf_across(cfg, f))
    if not f50 > 0.5:
        return None
    otf = lens_otf(cfg)
    why = "lens.diffraction = false: a perfect lens" if otf is None else f"the lens ({otf.source})"
    return (f"the system MTF50 across the track (lens x pixel aperture) is {f50:.3f} cycles/px, above "
            f"Nyquist (0.5): {why}; the images alias and are sharper than a real camera's")


def preflight_tasks(
    command: str,
    tasks: Iterable[tuple[BenchConfig, Sequence[int]]],
    *,
    out: str | os.PathLike[str] | None,
    workers: int | None,
    scheduler: str | None,
    disk_bytes: Mapping[str, int],
    hint: str,
    estimate: Callable[[BenchConfig, Sequence[int]], ResourceEstimate] = estimate_simulate,
) -> None:
    """Check a run of many simulation passes (sweep points, data-set samples) before any runs.

    The largest task (one pass with its truth, :func:`bench_sim.workflows.estimates.estimate_simulate`)
    times the worker processes that run at once on this machine
    (:func:`bench_sim.runtime.resources.local_concurrency`; none with a ``scheduler``: the cluster's
    machines run them) must fit in the memory available, and ``disk_bytes`` on the disk of
    ``out``; the target image and the backend (forced or chosen) are checked on the largest
    task's config (the backend only for local workers). The output folder itself is the
    caller's to check (resumable runs reuse theirs). ``estimate``: one task's resources from its
    config and stages, if a task holds more than one pass (``design``: its candidates' scores).
    """
    sized = [(estimate(cfg, stages), cfg) for cfg, stages in tasks]
    if not sized:
        return
    task, cfg = max(sized, key=lambda e: e[0].memory_total)
    est = estimate_tasks(command, task, local_concurrency(workers, scheduler), disk_bytes, hint)
    check_resources(est, out)
    preflight(cfg, out=None, estimate=None, render=scheduler is None)
