"""One pass: frames -> sensor -> DTDI -> stage images and their truth.

:func:`run_pass` renders the frames ``0 .. L + max(stages) - 2`` (``L = config.lines``), exposes
the rows ``0 .. max(stages) - 1`` of the sensor (EMVA 1288 model, :mod:`bench_sim.sensor.emva`)
through the one sensor + DTDI loop (:func:`bench_sim.sensor.stream.iter_stream`), accumulates
every requested stage (paper eq. 1-2, 4) and, from the same frames and the same physical sensor,
the truth (:mod:`bench_sim.sensor.stage_truth`). Its dataset (:class:`xarray.Dataset`,
dimensions ``stage``, ``line``, ``column``) holds the variables of :data:`PASS_VARIABLES`:

=============== ======================================================================
``dn``          stage words (``0 .. 2**beta - 1``; uint16 up to beta = 16, else uint32)
``mean_dn``     exact expectation of ``dn``: full-well, ADC and word clips included
                (:mod:`bench_sim.sensor.expectation`; fixed patterns in)
``linear_dn``   the linear model's expectation, no clip (what ``mean_dn`` was before)
``noise_std_dn``  temporal standard deviation of ``dn`` (every read's variance, the clips in)
``photons``     mean photons collected by the stage pixel (its ``m`` rows, smear in)
``reflectance`` target reflectance integrated by the pixel's ``m`` footprints
``clipped``     a read hit full well or the ADC top, or the word hit ``2**beta - 1``
``gamma_hdr``   eq. 11 fusion of stages ``fusion.mu1``, ``fusion.mu2`` (when both requested),
                every stage's offset removed (:func:`bench_sim.fusion.stage_pair.fuse_stage_words`)
``gamma_hdr_source``  the stage each ``gamma_hdr`` pixel came from
``true_hdr_dn``   with the truth: the true HDR target, ``linear_dn`` of ``mu2`` less its offsets
                (:func:`bench_sim.fusion.stage_pair.true_hdr_dn`): what an ideal HDR image holds
``eq11_expected_dn``  with the truth: eq. 11 of the expected words (not the truth)
``stage_clip_flags``  with the truth: bit 0 / bit 1 where stage ``mu1`` / ``mu2`` is not clear
                of its clips (:func:`bench_sim.metrics.fusion_truth.clear_of_clips`)
``hdr_recoverable``   with the truth: some fused stage is clear of its clips
``gamma_hdr_error``   with the truth: ``(gamma_hdr - T) / T``, ``T`` = ``true_hdr_dn`` (nan below 1 DN)
``tdi_light_ratio``   with the truth: ``r = (photons_mu2 / mu2) / (photons_mu1 / mu1)``, the TDI
                window's light ratio (eq. 11 assumes ``r = 1``; :mod:`bench_sim.metrics.fusion_truth`)
=============== ======================================================================

Coordinates, attributes (the resolved config as TOML text, its SHA-256, the seed, the version,
the engine, the Mitsuba variant, the sensor's constants), stored dtypes and chunks are the one
file schema of ``simulate`` and the data sets (:mod:`bench_sim.pipeline.store_schema`). Random
numbers come from one generator, drawn in a fixed order
(render seed, fixed pattern, then the seed of the temporal noise, from which every chunk of
frames spawns its own stream), so the same config and seed give identical data with any number
of threads. Rendering runs a chunk ahead in its own thread and the chunks of frames are exposed
on the thread pool (:mod:`bench_sim.runtime.parallel`) while the stages accumulate in order.

:data:`PASS_VARIABLES` is the one table of the pass's variables: the arrays the pass allocates,
the dataset's variables and units, the stored dtypes of ``simulate`` and the data sets and the
resource estimates
(:func:`stage_pixel_bytes`) all follow it.

A :class:`PassResult` gives its arrays, stages and attributes without the dataset
(:meth:`PassResult.read`, a :data:`Read`; :meth:`PassResult.values`, ``stages``, ``variables``,
``attrs``): the code a worker runs for a sweep point or a data set's sample reads them there and
never imports xarray (nor pandas, nor Dask's arrays), ~1 s of CPU per worker process.
"""

from bench_sim.pipeline.one_pass import (
    RENDER_CHUNK_FRAMES,
    SENSOR_CHUNK_FRAMES,
    TRUTH_BAND_LINES,
    PassResult,
    Read,
    pass_loops,
    run_pass,
)
from bench_sim.pipeline.store_schema import (
    CHUNK_PIXELS,
    COORD_ATTRS,
    constant_attrs,
    pass_attrs,
    pass_coords,
    physical_coords,
    store_chunks,
    stored_dataset,
)
from bench_sim.pipeline.variables import (
    IMAGE_DIMS,
    PASS_VARIABLES,
    STAGE_DIMS,
    VARIABLES_BY_NAME,
    WORD,
    Variable,
    pass_dtypes,
    pass_variables,
    stage_pixel_bytes,
    variable_attrs,
)

__all__ = [
    "run_pass", "PassResult", "Read", "Variable", "PASS_VARIABLES", "VARIABLES_BY_NAME", "STAGE_DIMS",
    "IMAGE_DIMS", "WORD", "pass_variables", "stage_pixel_bytes", "SENSOR_CHUNK_FRAMES",
    "RENDER_CHUNK_FRAMES", "TRUTH_BAND_LINES", "pass_dtypes", "pass_coords", "pass_attrs", "COORD_ATTRS",
    "pass_loops", "variable_attrs", "CHUNK_PIXELS", "constant_attrs", "physical_coords", "store_chunks",
    "stored_dataset",
]
