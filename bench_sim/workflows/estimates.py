"""Per-command resource estimates: the peak memory and output size of each command's run.

The estimates are closed forms over the config: array shapes times bytes per element (the pass's
arrays from :data:`bench_sim.pipeline.PASS_VARIABLES`), plus the fixed allowance for the
interpreter and its libraries (:data:`bench_sim.runtime.resources.BASE_PROCESS_BYTES`) and
per-element costs of the renderer calibrated against measured peaks
(``benchmarks/bench_resources.py`` prints estimate / measured for a few sizes). They aim to be
upper bounds within a factor of about two (2.9 measured at worst), so a run that is refused
would not have fitted. :func:`bench_sim.runtime.resources.check_resources` (through
:func:`bench_sim.workflows.preflight.preflight`) checks them against what is available.

Commands that run many tasks (sweeps, data sets) use :func:`estimate_tasks`: the largest task's
memory (one simulation pass with its truth, :func:`estimate_simulate`) times the tasks that run
at once on this machine (:func:`bench_sim.runtime.resources.local_concurrency`), and their
outputs' disk terms.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from bench_sim.config import BenchConfig
from bench_sim.errors import BenchSimError
from bench_sim.io import image_shape
from bench_sim.pipeline import (
    IMAGE_DIMS,
    RENDER_CHUNK_FRAMES,
    TRUTH_BAND_LINES,
    pass_variables,
    stage_pixel_bytes,
)
from bench_sim.render.texture import BLOCK_ROWS, CACHE_BLOCKS
from bench_sim.runtime.resources import BASE_MITSUBA_BYTES, BASE_PROCESS_BYTES, MiB, ResourceEstimate

__all__ = [
    "pass_memory",
    "target_memory",
    "estimate_render",
    "estimate_simulate",
    "estimate_design",
    "estimate_reproduce",
    "estimate_ptc",
    "estimate_area_ptc",
    "estimate_fuse",
    "estimate_tasks",
]

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
#: Lines of a streamed ``simulate`` held in memory beyond ``max(stages)``: the truth's band
#: (:data:`bench_sim.pipeline.TRUTH_BAND_LINES`), a block of lines and a row of Zarr chunks.
STREAMED_LINES = 4 * TRUTH_BAND_LINES + 256
#: Reference engine: Mitsuba's film and wavefront per pixel of a frame [bytes].
REFERENCE_BYTES_PER_PIXEL = 256


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
    chunk = RENDER_CHUNK_FRAMES  # frames rendered per chunk (bench_sim.pipeline)
    if name == "fast":
        # rasterised as the pass reaches it: the blocks a texture keeps, one block being
        # rasterised and a chunk's window (bench_sim.render.texture, bench_sim.render.engines)
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
    """(bytes of the stage words and truth, bytes per stage pixel) for ``stages`` in memory
    (:func:`bench_sim.pipeline.stage_pixel_bytes`)."""
    s = len(list(stages))
    pix = s * cfg.lines * cfg.sensor.columns
    per = stage_pixel_bytes(cfg.dtdi.beta_bits, truth=truth)  # words, truth
    return pix * per, per


def estimate_simulate(cfg: BenchConfig, stages: Iterable[int], fmt: str | None = None) -> ResourceEstimate:
    """``bench-sim simulate`` / :func:`bench_sim.simulate`: a pass with its truth, the dataset
    and its encoding for the file. ``fmt = "zarr"``: the store is written while the pass runs
    (:mod:`bench_sim.workflows.simulate_store`), so memory holds the lines in flight only (about
    ``max(stages)`` plus a band of the truth and a row of Zarr chunks, bounded here by
    :data:`STREAMED_LINES`); any other format (or ``None``: a pass kept in memory, as sweeps and
    data sets run it) holds every stage image."""
    st = sorted(int(m) for m in stages)
    frames = cfg.lines + st[-1] - 1
    n_pix = len(st) * cfg.lines * cfg.sensor.columns
    arrays, per = _stage_arrays(cfg, st, truth=True)
    mem = pass_memory(cfg, frames, rows=st[-1])
    images = pass_variables(IMAGE_DIMS, maps=True)
    image_bytes = sum(v.array_dtype(cfg.dtdi.beta_bits).itemsize for v in images)
    hdr = cfg.lines * cfg.sensor.columns * image_bytes
    if fmt == "zarr":
        held = min(cfg.lines, st[-1] + STREAMED_LINES)
        mem[f"lines in flight ({len(st)} stages x {held} x {cfg.sensor.columns})"] = (
            len(st) * held * cfg.sensor.columns * per + held * cfg.sensor.columns * image_bytes
        )
    else:
        mem[f"stage images and truth ({len(st)} stages x {cfg.lines} x {cfg.sensor.columns})"] = arrays + hdr
        mem["file encoding (largest variable)"] = n_pix * 8
    # on disk: the stored schema (the word in its smallest type, the truth in float32), uncompressed
    stored = stage_pixel_bytes(cfg.dtdi.beta_bits, truth=True, stored=True)
    image_stored = sum(v.stored_dtype(cfg.dtdi.beta_bits).itemsize for v in images)
    disk = {"stage images and truth": n_pix * stored,
            "hdr and maps": cfg.lines * cfg.sensor.columns * image_stored}
    return ResourceEstimate("simulate", mem, disk, _hint(cfg, f"the stages ({len(st)})"))


def estimate_design(cfg: BenchConfig, stages: Iterable[int]) -> ResourceEstimate:
    """One point of ``bench-sim design``: a pass with its truth at ``stages`` kept in memory
    (:func:`estimate_simulate`), and the candidates' arrays over those stages (float64 signals,
    truth, light per row, the word's, the clip flags and regions:
    :mod:`bench_sim.measure.design_scores`, two words' worth at once)."""
    st = sorted(int(m) for m in stages)
    est = estimate_simulate(cfg, st)
    n_pix = len(st) * cfg.lines * cfg.sensor.columns
    mem = dict(est.memory_bytes)
    mem[f"candidate arrays ({len(st)} stages x {cfg.lines} x {cfg.sensor.columns})"] = n_pix * (5 * 8 + 10)
    return ResourceEstimate("design", mem, {}, est.hint)


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


def estimate_area_ptc(rows: int, columns: int, frames: int) -> ResourceEstimate:
    """``bench-sim ptc --area``: the raw frames (uint16, and float64 stacks while analysed) and
    the compressed ``frames.npz``."""
    img = rows * columns
    mem = {"interpreter and libraries": BASE_PROCESS_BYTES, f"{frames} raw frames": frames * img * (2 + 8)}
    disk = {"frames.npz": frames * img * 2, "tables and plots": 2 * MiB}
    return ResourceEstimate("ptc --area", mem, disk, f"use a smaller window than {rows} x {columns}")


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
