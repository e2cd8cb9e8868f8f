"""File input/output with metadata: atomic writes, output sets, EXR, TIFF, PNG, NPY, JSON, CSV,
text and EMVA 1288 descriptor files.

Every file carries its provenance in one format (the dict of
:func:`bench_sim.runtime.provenance.provenance`: ``version``, ``seed``, ``config_sha256``,
``config``): as a JSON attribute (EXR header, TIFF ImageDescription, PNG ``tEXt`` chunk
``bench_sim``), as ``#`` comment lines (CSV, EMVA descriptors), or as keys (JSON).

Modules
-------
:mod:`~bench_sim.io.atomic`
    One file written under a temporary name and renamed into place (:func:`atomic_path`), the
    temporaries and their locks, write failures as one line, fault injection (tests).
:mod:`~bench_sim.io.outputs`
    Output sets (:func:`output_set`, :func:`output_files`) and the checks of an output before
    any work (folder, file, free space).
:mod:`~bench_sim.io.files`
    JSON and text files, SHA-256 digests, byte counts for messages.
:mod:`~bench_sim.io.images`
    EXR, TIFF, PNG and NPY images: writers, the one reader and the one input-file check.
:mod:`~bench_sim.io.tables`
    CSV files with provenance lines (and numeric CSV tables read), Markdown tables.
:mod:`~bench_sim.io.spectral_data`
    Measured spectra by name from colour-science, or from CSV files.
:mod:`~bench_sim.io.emva_descriptor`
    The EMVA 1288 descriptor file.
:mod:`~bench_sim.io.frame_stacks`
    Stacks of raw frames of an EMVA 1288 measurement in one ``.npz`` (``ptc --area`` writes it,
    ``calibrate`` reads it).
:mod:`~bench_sim.io.folder_lock`
    One writer per output folder: the advisory lock a long run holds on its ``--out``.
:mod:`~bench_sim.io.interrupts`
    Ctrl-C and SIGTERM held back while a step must not be cut in half.
"""

from __future__ import annotations

from bench_sim.io.atomic import OutputWriteError, atomic_path, umask, write_failure
from bench_sim.io.emva_descriptor import write_emva_descriptor
from bench_sim.io.files import (
    format_bytes,
    read_json,
    sha256_file,
    sha256_text,
    write_json,
    write_text,
)
from bench_sim.io.frame_stacks import read_frames_npz, write_frames_npz
from bench_sim.io.images import (
    ImageReadError,
    check_image_file,
    image_file_problem,
    image_shape,
    read_exr,
    read_image,
    read_image_channel,
    read_image_data,
    read_png_text,
    srgb_to_linear,
    write_exr,
    write_figure_png,
    write_png,
    write_tiff16,
)
from bench_sim.io.outputs import (
    OUTPUT_MARKER,
    check_free_space,
    check_output_dir,
    check_output_file,
    output_files,
    output_set,
    read_output_record,
)
from bench_sim.io.tables import markdown_table, read_csv_columns, write_csv

__all__ = [
    "atomic_path",
    "sha256_file",
    "output_set",
    "output_files",
    "check_output_dir",
    "check_output_file",
    "check_free_space",
    "format_bytes",
    "read_output_record",
    "write_failure",
    "OutputWriteError",
    "OUTPUT_MARKER",
    "write_json",
    "read_json",
    "write_exr",
    "read_exr",
    "write_tiff16",
    "write_png",
    "write_figure_png",
    "read_png_text",
    "write_text",
    "write_csv",
    "read_csv_columns",
    "write_emva_descriptor",
    "write_frames_npz",
    "read_frames_npz",
    "read_image",
    "read_image_channel",
    "srgb_to_linear",
    "read_image_data",
    "check_image_file",
    "image_file_problem",
    "image_shape",
    "sha256_text",
    "ImageReadError",
    "markdown_table",
    "umask",
]
