"""Up-front resource estimates: the memory and disk a run needs against what is available.

Every command estimates, before it computes anything, the peak memory of its run and the size
of the files it writes (:class:`ResourceEstimate`, one named term per large array), and
:func:`check_resources` refuses a run that cannot fit with one line giving the estimate, its
largest term, what is available and what to lower. The estimates are closed forms over the
config: array shapes times bytes per element, plus a fixed allowance for the interpreter and
its libraries and per-element costs of the renderer calibrated against measured peaks
(``benchmarks/bench_resources.py`` prints estimate / measured for a few sizes). They aim to be
upper bounds within a factor of about two (2.9 measured at worst), so a run that is refused
would not have fitted.

Available memory is the smallest of ``MemAvailable`` (``/proc/meminfo``), the cgroup limit less
its usage (containers, batch jobs) and ``RLIMIT_AS`` less the process's size; available disk is
the free space of the file system that receives the output (:func:`bench_sim.io.check_free_space`;
the temporary folder of an output set lies beside it, so the new set must fit next to the old
one).

Commands that run many tasks (sweeps, data sets) use :func:`estimate_tasks`: the largest task's
memory (one simulation pass with its truth, :func:`estimate_simulate`) times the tasks that run
at once on this machine, and their outputs' disk terms, then call :func:`check_resources`.
"""

from __future__ import annotations

import math
import os
import resource
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from bench_sim.errors import BenchSimError
from bench_sim.io import check_free_space, format_bytes

if TYPE_CHECKING:
    from bench_sim.config import BenchConfig

__all__ = [
    "ResourceEstimate",
    "ResourceError",
    "available_memory_bytes",
    "check_resources",
    "pass_memory",
    "target_memory",
    "estimate_render",
    "estimate_simulate",
    "estimate_reproduce",
    "estimate_ptc",
    "estimate_fuse",
    "estimate_tasks",
    "local_concurrency",
    "BASE_PROCESS_BYTES",
    "BASE_MITSUBA_BYTES",
]

MiB = 1 << 20
#: The interpreter with numpy, pydantic, matplotlib, xarray and the I/O libraries loaded (160 MiB
#: measured) [bytes].
BASE_PROCESS_BYTES = 200 * MiB
#: Extra for Mitsuba / Dr.Jit with its LLVM backend, the scene and the compiled kernels [bytes].
BASE_MITSUBA_BYTES = 150 * MiB
#: Run texture held whole (the reference engine's Mitsuba texture): rasterised values, Mitsuba's
#: copy and the rasteriser's temporaries, per texel of the pass [bytes] (about 10 measured).
TEXTURE_BYTES_PER_TEXEL = 24
#: Fast engine's texture per texel of a chunk's window: raw rows, smeared rows, phase planes [bytes].
WINDOW_BYTES_PER_TEXEL = 12
#: Rasteriser's work arrays per texel of the block being rasterised (float64 sums and painters).
RASTER_BYTES_PER_TEXEL = 40
#: Fast engine: Mitsuba's film and the records' float64 work arrays per record (sub-pixel sample
#: position), independent of ``spp`` (about 190 measured) [bytes].
RECORD_BYTES = 256
#: Reference engine: Mitsuba's film and wavefront per pixel of a frame [bytes].
REFERENCE_BYTES_PER_PIXEL = 256
#: Truth of a simulation per stage pixel: photons, mean_dn (float64), reflectance (float32),
#: clipped (bool) [bytes].
TRUTH_BYTES_PER_PIXEL = 8 + 8 + 4 + 1


class ResourceError(BenchSimError):
    """A run that would not fit in the memory or on the disk available (one line)."""


@dataclass(frozen=True)
class ResourceEstimate:
    """What a run needs.

    Attributes
    ----------
    command
        The command or run, for messages (``"render"``).
    memory_bytes
        Named terms of the peak memory [bytes] (they add up).
    disk_bytes
        Named terms of the output size [bytes].
    hint
        What to lower, naming the keys or options and their values (``"lower --frames (8)"``).
    """

    command: str
    memory_bytes: Mapping[str, int] = field(default_factory=dict)
    disk_bytes: Mapping[str, int] = field(default_factory=dict)
    hint: str = ""

    @property
    def memory_total(self) -> int:
        return int(sum(self.memory_bytes.values()))

    @property
    def disk_total(self) -> int:
        return int(sum(self.disk_bytes.values()))

    def largest(self, which: str) -> tuple[str, int]:
        """The largest memory or disk term, ``(name, bytes)``."""
        terms = self.memory_bytes if which == "memory" else self.disk_bytes
        return max(terms.items(), key=lambda kv: kv[1]) if terms else ("-", 0)


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_available() -> int | None:
    for limit, usage in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        lim = _read_int(limit)
        if lim is not None and lim < 1 << 60:
            return max(lim - (_read_int(usage) or 0), 0)
    return None


def _rlimit_available() -> int | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    size = 0
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                size = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return max(soft - size, 0)


def available_memory_bytes() -> tuple[int, str] | None:
    """Memory this process can still use [bytes] and where the bound comes from, or ``None``
    where nothing can be read (then no memory check is made)."""
    found = [
        (v, name)
        for v, name in (
            (_meminfo_available(), "MemAvailable"),
            (_cgroup_available(), "cgroup limit"),
            (_rlimit_available(), "ulimit -v"),
        )
        if v is not None
    ]
    return min(found) if found else None


def check_resources(
    est: ResourceEstimate, out: str | os.PathLike[str] | None = None, what: str = "--out"
) -> None:
    """Refuse a run that cannot fit: one line with the estimate, its largest term, what is
    available and :attr:`ResourceEstimate.hint`. ``out``: where the outputs go (the disk check,
    :func:`bench_sim.io.check_free_space`)."""
    mem = available_memory_bytes()
    if mem is not None and est.memory_total > mem[0]:
        name, size = est.largest("memory")
        raise ResourceError(
            f"not enough memory: {est.command} needs about {format_bytes(est.memory_total)} "
            f"(largest: {name}, {format_bytes(size)}) but {format_bytes(mem[0])} is available "
            f"({mem[1]}); {est.hint}"
        )
    if out is not None and est.disk_bytes:
        name, size = est.largest("disk")
        detail = f"{est.command}'s output, largest: {name}, {format_bytes(size)}; or {est.hint}"
        check_free_space(out, est.disk_total, what, detail)


# --- terms ---------------------------------------------------------------------------------------


def target_memory(cfg: BenchConfig) -> dict[str, int]:
    """Memory of the target panel itself [bytes]: the texture map of the map layouts
    (``(panel_lines q) x (panel_columns q)`` texels with the generator's or the image
    resampler's work arrays), or the text bitmap of the ``paper`` layout."""
    t = cfg.target
    q = t.texels_per_pixel
    if t.layout == "paper":
        # text box: 8 % of the panel height x 70 % of a half panel, 8 samples per pixel (uint8 +
        # float32)
        rows = max(int(0.08 * t.panel_lines * 8), 8)
        cols = max(int(0.35 * t.panel_columns * 8), 8)
        return {"target text bitmap": rows * cols * 5}
    if t.layout == "uniform":
        return {}
    texels = t.panel_lines * q * t.panel_columns * q
    per_texel = {"image": 24, "dead_leaves": 13, "slanted_edges": 8, "random_bars": 8}[t.layout]
    terms = {f"target panel map ({t.panel_lines * q} x {t.panel_columns * q} texels)": texels * per_texel}
    if t.layout == "image" and t.image:
        from bench_sim.io import image_shape

        try:
            shape = image_shape(t.image)
        except BenchSimError:
            shape = None
        if shape is not None:
            terms["target image decoded"] = math.prod(shape) * 8 * 2
    return terms


def _texture_shape(cfg: BenchConfig, frames: int) -> tuple[float, int]:
    """(rows, columns) of the run texture of ``frames`` line periods."""
    q = cfg.target.texels_per_pixel
    margin = 6  # object pixels of margin on each side (bench_sim.render.texture)
    ny = q * (frames * (1.0 + abs(cfg.timing.sync_error)) + cfg.sensor.rows + 2 * margin + 2)
    nx = q * (1.01 * cfg.sensor.columns + 2 * margin) + 1
    return ny, int(nx)


def _texture_texels(cfg: BenchConfig, frames: int) -> int:
    ny, nx = _texture_shape(cfg, frames)
    return int(ny * nx)


def pass_memory(
    cfg: BenchConfig, frames: int, *, engine: str | None = None, rows: int | None = None
) -> dict[str, int]:
    """Memory terms of rendering ``frames`` line periods [bytes]: the interpreter and Mitsuba,
    the target, the run texture, the engine's records or render wavefront and the frame chunks
    (``rows``: sensor rows exposed, default all)."""
    s, r = cfg.sensor, cfg.render
    m, n = s.rows, s.columns
    name = engine or r.engine
    terms = {"interpreter, Mitsuba and libraries": BASE_PROCESS_BYTES + BASE_MITSUBA_BYTES}
    terms.update(target_memory(cfg))
    texels = _texture_texels(cfg, frames)
    whole = texels * TEXTURE_BYTES_PER_TEXEL
    chunk = 64  # frames rendered per chunk (bench_sim.workflows.simulate)
    if name == "fast":
        # rasterised as the pass reaches it: the blocks a texture keeps, one block being
        # rasterised and a chunk's window (bench_sim.render.texture, bench_sim.render.engines)
        from bench_sim.render.texture import BLOCK_ROWS, CACHE_BLOCKS

        q, nx = cfg.target.texels_per_pixel, _texture_shape(cfg, frames)[1]
        window = q * (m + chunk + 8) * nx * WINDOW_BYTES_PER_TEXEL
        streamed = (CACHE_BLOCKS * 4 + RASTER_BYTES_PER_TEXEL) * BLOCK_ROWS * nx + window
        terms["run texture (blocks of rows kept, a chunk's window)"] = min(whole, streamed)
    else:
        terms[f"run texture ({texels:,} texels for {frames:,} frames)"] = whole
    if name == "fast":
        terms[f"fast-engine records ({r.subpixels}^2 per pixel)"] = m * n * r.subpixels**2 * RECORD_BYTES
    else:
        terms["reference render"] = m * n * REFERENCE_BYTES_PER_PIXEL
    terms["frame chunks"] = chunk * (rows or m) * n * (4 + 8 + 8 + 1)
    return terms


def _hint(cfg: BenchConfig, *extra: str) -> str:
    keys = [*extra, f"lines ({cfg.lines})", f"sensor.columns ({cfg.sensor.columns})"]
    return "lower " + " or ".join(keys)


def estimate_render(cfg: BenchConfig, frames: int, engine: str | None = None) -> ResourceEstimate:
    """``bench-sim render``: the whole pass of photons is held, concatenated and written."""
    m, n = cfg.sensor.rows, cfg.sensor.columns
    photons = frames * m * n * 4
    lines = max(frames - m + 1, 0)
    mem = pass_memory(cfg, frames, engine=engine)
    mem[f"photons of {frames:,} frames x {m} x {n} (float32, chunks and whole)"] = 2 * photons
    mem["ground truth"] = lines * n * 8 * 4
    disk = {"exposures.exr": photons, "ground_truth.exr": lines * n * 4, "meta.json": 64 * 1024}
    return ResourceEstimate("render", mem, disk, f"lower --frames ({frames}) or sensor.columns ({n})")


def _stage_arrays(cfg: BenchConfig, stages: Iterable[int], truth: bool) -> tuple[int, int]:
    """(bytes of the stage words and truth, bytes per stage pixel) for ``stages``."""
    from bench_sim.sensor.model import word_dtype

    s = len(list(stages))
    pix = s * cfg.lines * cfg.sensor.columns
    per = word_dtype(cfg.dtdi.beta_bits).itemsize + (TRUTH_BYTES_PER_PIXEL if truth else 0)  # words, truth
    return pix * per, per


def estimate_simulate(cfg: BenchConfig, stages: Iterable[int], fmt: str = "zarr") -> ResourceEstimate:
    """``bench-sim simulate`` / :func:`bench_sim.simulate`: a pass with its truth, the dataset
    and its encoding for the file."""
    st = sorted(int(m) for m in stages)
    frames = cfg.lines + st[-1] - 1
    n_pix = len(st) * cfg.lines * cfg.sensor.columns
    arrays, _ = _stage_arrays(cfg, st, truth=True)
    mem = pass_memory(cfg, frames, rows=st[-1])
    mem[f"stage images and truth ({len(st)} stages x {cfg.lines} x {cfg.sensor.columns})"] = arrays
    mem["file encoding (largest variable)"] = n_pix * 8
    hdr = cfg.lines * cfg.sensor.columns * (4 + 2)
    disk = {"stage images and truth": n_pix * (4 + TRUTH_BYTES_PER_PIXEL), "hdr": hdr}
    return ResourceEstimate("simulate", mem, disk, _hint(cfg, f"the stages ({len(st)})"))


def estimate_reproduce(cfg: BenchConfig, stages: Iterable[int]) -> ResourceEstimate:
    """``bench-sim reproduce``: a pass of every Fig. 3 stage (no truth), fusion, metrics,
    figures and the whole-chain DR measurement (fixed size)."""
    st = sorted(int(m) for m in stages)
    frames = cfg.lines + st[-1] - 1
    img = cfg.lines * cfg.sensor.columns
    arrays, _ = _stage_arrays(cfg, st, truth=False)
    mem = pass_memory(cfg, frames, rows=st[-1])
    mem[f"stage images ({len(st)} stages x {cfg.lines} x {cfg.sensor.columns})"] = arrays
    mem["fusion, metrics and figure images"] = img * 8 * 12  # figures draw display-size copies
    mem["figures and DR measurement"] = 150 * MiB
    disk = {
        "gamma1/2.tiff": 2 * img * 2, "gamma_hdr.exr": img * 8, "PNG images and figures": img * 2 + 8 * MiB
    }
    return ResourceEstimate("reproduce", mem, disk, _hint(cfg))


def estimate_ptc(
    stages: Iterable[int], levels: int, lines: int, columns: int, spatial_images: int
) -> ResourceEstimate:
    """``bench-sim ptc``: image pairs of every level and the spatial stacks of every stage
    (uint32 in memory, 16-bit TIFF on disk)."""
    s = len(list(stages))
    img = lines * columns
    images = s * ((levels + 1) * 2 + 2 * spatial_images)
    mem = {"interpreter and libraries": BASE_PROCESS_BYTES, f"{images} stage images": images * img * 4 * 2}
    disk = {f"{images} 16-bit TIFF images": images * (img * 2 + 4096), "tables and plots": 2 * MiB}
    hint = f"lower the stages ({s}) or the image size ({lines} x {columns})"
    return ResourceEstimate("ptc", mem, disk, hint)


def estimate_fuse(shape: tuple[int, ...], tra: bool) -> ResourceEstimate:
    """``bench-sim fuse``: two stage images as float64, eq. 11's arrays, the display transform."""
    px = math.prod(shape)
    mem = {
        "interpreter and libraries": BASE_PROCESS_BYTES,
        f"two stage images {tuple(shape)} (decoded, float64)": px * 2 * (8 + 8),
        "fusion (hdr, source, masks)": px * 24,
    }
    if tra:
        mem["display transform"] = px * 8 * 3
    disk = {"HDR EXR (2 channels)": px * 8}
    if tra:
        disk["Gamma_TRA PNG"] = px
    return ResourceEstimate("fuse", mem, disk, f"use smaller images than {tuple(shape)}")


def local_concurrency(workers: int | None, scheduler: str | None) -> int:
    """Tasks that run at once on this machine: ``workers`` local worker processes (default:
    the usable cores; ``0``: in this process, one at a time), or ``0`` with a scheduler (the
    tasks run on the cluster's machines, whose memory this machine cannot see)."""
    if scheduler is not None:
        return 0
    if workers is None:
        from bench_sim.runtime.execution import default_workers

        return default_workers()
    return max(int(workers), 1)


def estimate_tasks(
    command: str,
    task: ResourceEstimate,
    concurrent: int,
    disk_bytes: Mapping[str, int],
    hint: str,
) -> ResourceEstimate:
    """A run of many tasks (a sweep's points, a data set's samples): ``concurrent`` worker
    processes on this machine each hold the largest task's memory (``task``, e.g.
    :func:`estimate_simulate` of it; ``concurrent = 0``: none here, the tasks run on a cluster),
    plus this process, which gathers the results; ``disk_bytes``: the run's outputs."""
    mem: dict[str, int] = {"this process (client, results)": BASE_PROCESS_BYTES}
    if concurrent > 0:
        mem[f"{concurrent} worker process(es) x one {task.command} task"] = concurrent * task.memory_total
    return ResourceEstimate(command, mem, dict(disk_bytes), hint)
