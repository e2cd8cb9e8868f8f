"""Every bad input a user can give is one line on stderr, exit status 2, and leaves no output.

In-process (typer's ``CliRunner``): configs (every float of every section non-finite, refused
physical combinations, malformed files), command-line arguments, output paths, resources (runs
that cannot fit), image inputs of ``fuse`` and the environment (forced variants, the probe
cache). Each case checks the three parts of the contract: exit status 2, exactly one line
starting ``bench-sim: error:`` that names the key, file or option, and no file left behind.
"""

from __future__ import annotations

import math
import os
import shutil
import struct
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.config import DEFAULT_CONFIG_PATH, config_to_toml_dict, load_config
from bench_sim.runtime import backend, resources
from bench_sim.runtime.backend import ProbeResult

runner = CliRunner()

TINY = (
    f"base = '{DEFAULT_CONFIG_PATH}'\nlines = 8\n"
    "[sensor]\nrows = 12\ncolumns = 48\n[target]\npanel_lines = 96\npanel_columns = 48\n"
    "[render]\nspp = 4\n[fusion]\nmu1 = 2\nmu2 = 8\n"
)
#: stages that fit the tiny sensor, per command
STAGES = {"simulate": ["--stages", "2,8"], "ptc": ["--stages", "1,2"]}
#: reproduce needs the paper target's wedge and bars in view
REPRODUCIBLE = "lines = 600\n[target]\npanel_lines = 256\n"


def _cfg(folder: Path, extra: str = "") -> Path:
    """``tiny.toml``: the tiny bench (``base.toml``) with ``extra`` TOML on top."""
    (folder / "base.toml").write_text(TINY)
    path = folder / "tiny.toml"
    path.write_text("base = 'base.toml'\n" + extra)
    return path


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def assert_refused(result: Any, folder: Path, before: set[str], *needles: str) -> None:
    """Exit 2, one line ``bench-sim: error: ...`` holding every needle, ``folder`` unchanged."""
    err = result.stderr
    assert result.exit_code == 2, (result.exit_code, result.stdout[-500:], err[-2000:])
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert _files(folder) == before, "files were left behind"


def _toml_value(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def _override(path: tuple[Any, ...], value: Any) -> str:
    """TOML text setting ``path`` (section keys, then a key, then list indices) to ``value``."""
    keys = [p for p in path if isinstance(p, str)]
    idx = [p for p in path if isinstance(p, int)]
    if idx:  # a list element: write the whole list with one element replaced
        cur: Any = config_to_toml_dict(load_config())
        for k in keys:
            cur = cur[k]
        cur = [list(x) if isinstance(x, list) else x for x in cur]
        if len(idx) == 1:
            cur[idx[0]] = value
        else:
            cur[idx[0]][idx[1]] = value
        value = cur
    table, key = ".".join(keys[:-1]), keys[-1]
    head = f"[{table}]\n" if table else ""
    return f"{head}{key} = {_toml_value(value)}\n"


# ------------------------------------------------------------------ every float, non-finite
def _float_paths() -> list[tuple[Any, ...]]:
    """Every float of the default config (in tuples too), plus the optional float keys."""

    def walk(x: Any, path: tuple[Any, ...]) -> Any:
        if isinstance(x, dict):
            for k, v in x.items():
                yield from walk(v, (*path, k))
        elif isinstance(x, list):
            for i, v in enumerate(x):
                yield from walk(v, (*path, i))
        elif isinstance(x, float):
            yield path

    found = list(walk(config_to_toml_dict(load_config()), ()))
    return [*found, ("lens", "focus_distance_m"), ("timing", "integration_time_s")]


FLOAT_PATHS = _float_paths()
NON_FINITE = (math.inf, math.nan, -math.inf)


def _key_name(path: tuple[Any, ...]) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


@pytest.mark.parametrize(
    ("path", "value"),
    [(p, NON_FINITE[i % 3]) for i, p in enumerate(FLOAT_PATHS)],
    ids=[_key_name(p) for p in FLOAT_PATHS],
)
def test_every_float_must_be_finite(tmp_path: Path, path: tuple[Any, ...], value: float) -> None:
    cfg = _cfg(tmp_path, _override(path, value))
    before = _files(tmp_path)
    r = runner.invoke(app, ["render", str(cfg), "--frames", "2", "--out", str(tmp_path / "out")])
    assert_refused(r, tmp_path, before, _key_name(path), "finite")


def test_the_float_list_covers_every_section() -> None:
    """New sections are covered by the base model's ``allow_inf_nan=False``; this list is built
    from the config itself, so it grows with it."""
    assert {p[0] for p in FLOAT_PATHS} >= {"drum", "lens", "target", "lights", "sensor", "timing", "render"}
    assert len(FLOAT_PATHS) >= 45


# ------------------------------------------------------------------ other bad configs
BAD_CONFIGS: list[tuple[str, str, list[str]]] = [
    ("black at ADC top", "[sensor]\nblack_offset_dn = 1023\n", ["black_offset_dn = 1023", "ADC"]),
    ("black above ADC top", "[sensor]\nblack_offset_dn = 5000\n", ["black_offset_dn = 5000"]),
    # (inside the plausibility ranges of bench_sim.config.plausible, so the cross-check answers)
    ("dark saturates", "[sensor]\ndark_current_e_s = 9e5\n[timing]\nline_period_s = 0.02\n",
     ["dark_current_e_s", "saturates in the dark"]),
    ("dark over long t_int", "[timing]\nline_period_s = 0.09\n[sensor]\ndark_current_e_s = 2e5\n",
     ["dark_current_e_s", "t_int"]),
    ("mu2 beyond rows", "[fusion]\nmu2 = 200\n", ["fusion.mu2 = 200", "sensor.rows"]),
    ("mu1 >= mu2", "[fusion]\nmu1 = 8\nmu2 = 2\n", ["mu1 = 8", "mu2 = 2"]),
    ("no real image", "[lens]\nworking_distance_m = 0.01\n", ["working_distance_m = 0.01", "focal_length_m"]),
    ("focus inside f", "[lens]\nfocus_distance_m = 0.01\n", ["focus_distance_m = 0.01"]),
    ("reflectance order", "[target]\nreflectance_min = 0.95\n", ["reflectance_min = 0.95"]),
    ("beam wider than cutoff", "[lights.strong]\nbeam_width_deg = 5.0\n", ["beam_width_deg = 5.0"]),
    ("spot at its aim", "[lights.strong]\nposition_m = [-0.0155, 0.0, 0.1]\n", ["position_m", "aim point"]),
    ("spot inside drum", "[lights.strong]\nposition_m = [0.0, 0.0, 0.05]\n", ["position_m", "inside the"]),
    ("pedestal fills word", "[dtdi]\npedestal_dn = 3000\n", ["pedestal_dn = 3000"]),
    ("t_int > period", "[timing]\nintegration_time_s = 0.05\n", ["integration_time_s = 0.05"]),
    ("band outside", "[render]\nband_m = [300e-9, 900e-9]\n", ["band_m"]),
    ("qe curve short", "[sensor]\nqe_curve = [[5e-7, 0.5]]\n", ["qe_curve"]),
    ("qe curve > 1", "[sensor]\nqe_curve = [[4e-7, 0.5], [6e-7, 1.5]]\n", ["qe_curve"]),
    ("wavelength off band", "[render]\nspectral = true\n[sensor]\nwavelength_m = 9e-7\n", ["wavelength_m"]),
    ("drum too short", "[drum]\nlength_m = 0.001\n", ["drum.length_m = 0.001"]),
    ("unknown key", "[sensor]\nbogus = 1\n", ["unknown key 'sensor.bogus'"]),
    ("unknown section", "[bogus]\nx = 1\n", ["unknown key 'bogus'"]),
    ("string for int", "[sensor]\nrows = 'ten'\n", ["sensor.rows = 'ten'"]),
    ("rows 0", "[sensor]\nrows = 0\n", ["sensor.rows = 0"]),
    ("columns huge", "[sensor]\ncolumns = 100000\n", ["sensor.columns = 100000"]),
    ("lines 0", "lines = 0\n", ["lines = 0"]),
    ("lines huge int", "lines = 99999999999999999999\n", ["lines = "]),
    ("image layout, no image", "[target]\nlayout = 'image'\n", ["target.image"]),
    ("image missing", "[target]\nlayout = 'image'\nimage = 'missing.png'\n", ["missing.png"]),
    ("layout unknown", "[target]\nlayout = 'hexagons'\n", ["target.layout = 'hexagons'"]),
    ("f-number negative", "[lens]\nf_number = -2\n", ["lens.f_number = -2"]),
    ("vector too short", "[lights.strong]\nposition_m = [1.0, 2.0]\n", ["position_m"]),
    ("variant garbage", "[render]\nvariant = 'llvm_garbage'\n", ["variant = 'llvm_garbage'"]),
    ("variant other mode", "[render]\nvariant = 'llvm_ad_spectral'\n", ["llvm_ad_spectral", "mono"]),
    ("engine unknown", "[render]\nengine = 'magic'\n", ["render.engine = 'magic'"]),
    ("beta 40", "[dtdi]\nbeta_bits = 40\n", ["dtdi.beta_bits = 40"]),
    ("adc 0", "[sensor]\nadc_bits = 0\n", ["sensor.adc_bits = 0"]),
    ("sync error", "[timing]\nsync_error = 0.6\n", ["timing.sync_error = 0.6"]),
    ("wedge steps", "[target]\nwedge_steps = 3\n", ["target.wedge_steps = 3"]),
    ("name not text", "name = 5\n", ["name = 5"]),
    ("section not a table", "sensor = 5\n", ["sensor"]),
    ("dead leaves radii", "[target]\ndead_leaves_radius_min_px = 100.0\n", ["dead_leaves_radius_min_px"]),
    ("cutoff 0", "[lights.strong]\ncutoff_deg = 0.0\n", ["cutoff_deg = 0.0"]),
    ("negative irradiance", "[lights.weak]\nirradiance_w_m2 = -1.0\n", ["irradiance_w_m2 = -1.0"]),
    ("full well 0", "[sensor]\nfull_well_e = 0\n", ["full_well_e = 0"]),
    ("prnu 0.9", "[sensor]\nprnu = 0.9\n", ["prnu = 0.9"]),
    ("texels 64", "[target]\ntexels_per_pixel = 64\n", ["texels_per_pixel = 64"]),
    ("lens model", "[lens]\nmodel = 'fisheye'\n", ["lens.model = 'fisheye'"]),
    ("spp 0", "[render]\nspp = 0\n", ["render.spp = 0"]),
    ("tra unknown", "[fusion]\ntra = 'sepia'\n", ["fusion.tra = 'sepia'"]),
    ("bool for float", "[sensor]\nprnu = 'a lot'\n", ["sensor.prnu"]),
]


@pytest.mark.parametrize(("toml", "needles"), [c[1:] for c in BAD_CONFIGS], ids=[c[0] for c in BAD_CONFIGS])
def test_bad_config_values(tmp_path: Path, toml: str, needles: list[str]) -> None:
    cfg = _cfg(tmp_path, toml)
    before = _files(tmp_path)
    r = runner.invoke(app, ["render", str(cfg), "--frames", "2", "--out", str(tmp_path / "out")])
    assert_refused(r, tmp_path, before, *needles)


def _write(name: str, data: bytes) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        (folder / name).write_bytes(data)
        return folder / name

    return make


def _base_loop(folder: Path) -> Path:
    (folder / "a.toml").write_text("base = 'b.toml'\n")
    (folder / "b.toml").write_text("base = 'a.toml'\n")
    return folder / "a.toml"


BAD_FILES: list[tuple[str, Callable[[Path], Path], list[str]]] = [
    ("binary", _write("bin.toml", b"\xff\xfe\x00\x01binary"), ["bin.toml", "UTF-8"]),
    ("latin-1", _write("latin.toml", "# caf\xe9\nlines = 5\n".encode("latin-1")), ["latin.toml", "0xe9"]),
    ("NUL bytes", _write("nul.toml", b"[sensor]\x00\nrows = 5\n"), ["nul.toml", "NUL"]),
    ("not TOML", _write("bad.toml", b"[sensor]\nrows = [\n"), ["bad.toml", "not valid TOML"]),
    ("base missing", _write("b.toml", b"base = 'nope.toml'\n"), ["nope.toml", "no such file"]),
    ("base not text", _write("b.toml", b"base = 5\n"), ["base = 5"]),
    ("base loop", _base_loop, ["loops back"]),
    ("folder", lambda f: (f / "adir.toml").mkdir() or f / "adir.toml", ["adir.toml", "folder"]),
    ("missing", lambda f: f / "missing.toml", ["missing.toml", "no such file"]),
    # special files: named as such (before: "no such file"; a FIFO is never opened, it would wait)
    ("fifo", lambda f: os.mkfifo(f / "pipe.toml") or f / "pipe.toml", ["pipe.toml", "a FIFO (named pipe)"]),
    ("device", lambda f: Path("/dev/zero"), ["/dev/zero", "a character device"]),
]


@pytest.mark.parametrize(("make", "needles"), [c[1:] for c in BAD_FILES], ids=[c[0] for c in BAD_FILES])
def test_bad_config_files(tmp_path: Path, make: Callable[[Path], Path], needles: list[str]) -> None:
    cfg = make(tmp_path)
    before = _files(tmp_path)
    r = runner.invoke(app, ["render", str(cfg), "--out", str(tmp_path / "out")])
    assert_refused(r, tmp_path, before, *needles)


# ------------------------------------------------------------------ arguments
BAD_ARGS: list[tuple[str, list[str], list[str]]] = [
    ("seed -1", ["render", "{cfg}", "--seed", "-1"], ["--seed", "-1"]),
    ("seed 2**64", ["simulate", "{cfg}", "--seed", str(2**64)], ["--seed"]),
    ("seed text", ["ptc", "{cfg}", "--seed", "abc"], ["--seed", "abc"]),
    ("frames 0", ["render", "{cfg}", "--frames", "0"], ["--frames = 0"]),
    ("frames -5", ["render", "{cfg}", "--frames", "-5"], ["--frames = -5"]),
    ("frames text", ["render", "{cfg}", "--frames", "abc"], ["--frames"]),
    ("engine", ["render", "{cfg}", "--engine", "magic"], ["--engine = 'magic'"]),
    ("unknown option", ["render", "{cfg}", "--frmes", "3"], ["No such option: --frmes", "render"]),
    ("unknown command", ["rendr"], ["No such command 'rendr'"]),
    ("extra argument", ["render", "{cfg}", "extra"], ["extra"]),
    ("ptc stage 0", ["ptc", "{cfg}", "--stages", "0"], ["--stages = '0'"]),
    ("ptc stage > rows", ["ptc", "{cfg}", "--stages", "1,13"], ["--stages = '1,13'", "1..12"]),
    ("ptc stages text", ["ptc", "{cfg}", "--stages", "a,b"], ["--stages = 'a,b'"]),
    ("ptc range step 0", ["ptc", "{cfg}", "--stages", "5:1:0"], ["--stages = '5:1:0'"]),
    ("simulate stage twice", ["simulate", "{cfg}", "--stages", "2,2"], ["stage 2 is given twice"]),
    ("simulate stage > rows", ["simulate", "{cfg}", "--stages", "2,80"], ["stage 80", "sensor.rows = 12"]),
    ("simulate stages empty", ["simulate", "{cfg}", "--stages", ""], ["--stages"]),
    ("simulate format", ["simulate", "{cfg}", "--format", "hdf9"], ["--format = 'hdf9'"]),
    ("fuse missing argument", ["fuse", "{d}/low.npy"], ["Missing argument", "fuse"]),
    ("reproduce layout", ["reproduce", "{cfg}"], ["lines = 8", "wedge"]),
    ("fuse mu order", ["fuse", "{d}/low.npy", "{d}/high.npy", "--mu1", "9", "--mu2", "3"], ["--mu1 = 9"]),
    ("fuse pedestal", ["fuse", "{d}/low.npy", "{d}/high.npy", "--pedestal", "inf"], ["--pedestal = inf"]),
    ("fuse tra method", ["fuse", "{d}/low.npy", "{d}/high.npy", "--tra-method", "x"], ["'x'"]),
]


def _inputs(folder: Path, extra: str = "") -> Path:
    cfg = _cfg(folder, extra)
    np.save(folder / "low.npy", np.full((4, 5), 100, dtype=np.uint16))
    np.save(folder / "high.npy", np.full((4, 5), 800, dtype=np.uint16))
    # a sweep and a dataset of the tiny bench (two points / two samples, in this process)
    (folder / "sweep.toml").write_text(
        f"base = '{cfg.name}'\nseed = 1\n[[parameters]]\nkey = 'lights.strong.irradiance_w_m2'\n"
        "values = [64.0, 128.0]\n"
    )
    (folder / "dataset.toml").write_text(
        f"base = '{cfg.name}'\nsamples = 2\nseed = 1\nstages = [2, 8]\nlines = 8\ncolumns = 48\n"
        "[randomize]\n'lights.weak.irradiance_w_m2' = { dist = 'uniform', low = 2.0, high = 12.0 }\n"
    )
    return cfg


def _command_args(command: str, folder: Path, cfg: Path) -> list[str]:
    """The command line of ``command`` on the tiny inputs of :func:`_inputs`, into ``out``."""
    if command == "fuse":
        return ["fuse", str(folder / "low.npy"), str(folder / "high.npy"), "--out", str(folder / "o.exr")]
    if command in ("sweep", "dataset"):
        return [command, str(folder / f"{command}.toml"), "--out", str(folder / "out"), "--workers", "0"]
    return [command, str(cfg), *STAGES.get(command, []), "--out", str(folder / "out")]


@pytest.mark.parametrize(("args", "needles"), [c[1:] for c in BAD_ARGS], ids=[c[0] for c in BAD_ARGS])
def test_bad_arguments(tmp_path: Path, args: list[str], needles: list[str]) -> None:
    cfg = _inputs(tmp_path)
    args = [a.replace("{cfg}", str(cfg)).replace("{d}", str(tmp_path)) for a in args]
    if args[0] != "fuse" or len(args) > 2:
        args += ["--out", str(tmp_path / ("o.exr" if args[0] == "fuse" else "out"))]
    before = _files(tmp_path)
    r = runner.invoke(app, args)
    assert_refused(r, tmp_path, before, *needles)


# ------------------------------------------------------------------ output paths
def _file_at(name: str) -> Callable[[Path], str]:
    def make(folder: Path) -> str:
        (folder / name).write_text("a file")
        return str(folder / name)

    return make


def _foreign_folder(folder: Path) -> str:
    (folder / "mine").mkdir()
    (folder / "mine" / "thesis.tex").write_text("precious")
    return str(folder / "mine")


BAD_OUTS: list[tuple[str, Callable[[Path], str], list[str]]] = [
    ("out is a file", _file_at("taken"), ["--out", "is a file"]),
    ("out under a file", lambda f: _file_at("plain")(f) + "/sub/dir", ["--out", "plain is a file"]),
    ("out foreign folder", _foreign_folder, ["--out", "not written by bench_sim"]),
    ("out is cwd", lambda f: ".", ["--out", "current folder"]),
    ("out is root", lambda f: "/", ["--out", "current folder or holds it"]),
    ("out empty", lambda f: "", ["--out", "current folder"]),
    ("out in /sys (no permission)", lambda f: "/sys/bench_sim_out", ["--out", "/sys"]),
    ("out in /proc", lambda f: "/proc/bench_sim_out", ["--out", "/proc"]),
]


@pytest.mark.parametrize("command", ["render", "simulate", "ptc", "reproduce"])
@pytest.mark.parametrize(("make", "needles"), [c[1:] for c in BAD_OUTS], ids=[c[0] for c in BAD_OUTS])
def test_bad_output_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str, make: Callable[[Path], str],
    needles: list[str],
) -> None:
    cfg = _inputs(tmp_path, REPRODUCIBLE if command == "reproduce" else "")
    monkeypatch.chdir(tmp_path)
    out = make(tmp_path)
    before = _files(tmp_path)
    r = runner.invoke(app, [command, str(cfg), *STAGES.get(command, []), "--out", out])
    assert_refused(r, tmp_path, before, *needles)


BAD_FUSE_OUTS: list[tuple[str, list[str], list[str]]] = [
    ("suffix", ["--out", "{d}/o.png"], ["--out", ".exr"]),
    ("dir", ["--out", "{d}/adir.exr"], ["--out", "directory"]),
    ("under a file", ["--out", "{d}/low.npy/o.exr"], ["--out", "not a directory"]),
    ("in /sys", ["--out", "/sys/bench_sim.exr"], ["--out", "/sys"]),
    ("tra under a file", ["--out", "{d}/o.exr", "--tra", "{d}/low.npy/t.png"], ["--tra"]),
    ("tra is out", ["--out", "{d}/o.exr", "--tra", "{d}/o.exr"], ["--tra", ".png"]),
]


@pytest.mark.parametrize(
    ("opts", "needles"), [c[1:] for c in BAD_FUSE_OUTS], ids=[c[0] for c in BAD_FUSE_OUTS]
)
def test_bad_fuse_outputs(tmp_path: Path, opts: list[str], needles: list[str]) -> None:
    _inputs(tmp_path)
    (tmp_path / "adir.exr").mkdir()
    before = _files(tmp_path)
    opts = [o.replace("{d}", str(tmp_path)) for o in opts]
    r = runner.invoke(app, ["fuse", str(tmp_path / "low.npy"), str(tmp_path / "high.npy"), *opts])
    assert_refused(r, tmp_path, before, *needles)


# ------------------------------------------------------------------ resources
def _huge_npy(folder: Path, side: int = 46_000) -> Path:
    """A ``side``^2 16-bit NPY: a sparse file whose header alone says 4.2 GB of pixels (below
    the header bound, :data:`bench_sim.io.image_header.MAX_IMAGE_PIXELS`: the memory check
    refuses it, about 120 GB decoded)."""
    path = folder / "huge.npy"
    np.lib.format.open_memmap(path, mode="w+", dtype=np.uint16, shape=(side, side))
    return path


HUGE: list[tuple[str, list[str], str, list[str]]] = [
    ("render 10^8 frames", ["render", "{cfg}", "--frames", "100000000"], "", ["not enough memory", "frames"]),
    # the Zarr store is written while the pass runs: memory fits, the disk does not
    ("simulate 10^6 lines x 16384", ["simulate", "{cfg}"], "lines = 1000000\n[sensor]\ncolumns = 16384\n"
     "[target]\npanel_columns = 16384\n[drum]\nlength_m = 4.0\n", ["TiB", "free space", "lines (1000000)"]),
    # NetCDF is written from memory: every stage image must fit first
    ("simulate 10^6 lines x 16384 to NetCDF", ["simulate", "{cfg}", "--format", "netcdf"],
     "lines = 1000000\n[sensor]\ncolumns = 16384\n[target]\npanel_columns = 16384\n[drum]\nlength_m = 4.0\n",
     ["not enough memory", "lines (1000000)"]),
    ("65536^2 paper panel", ["render", "{cfg}"], "[target]\npanel_lines = 65536\npanel_columns = 65536\n",
     ["not enough memory", "target text bitmap"]),
    ("65536^2 dead leaves", ["simulate", "{cfg}"],
     "[target]\nlayout = 'dead_leaves'\npanel_lines = 65536\npanel_columns = 65536\n",
     ["not enough memory", "target panel map"]),
    # the render streams its texture, so what cannot fit is the run's images: 10^6 lines x 1024
    ("reproduce 10^6 lines", ["reproduce", "{cfg}"],
     "lines = 1000000\n[sensor]\ncolumns = 1024\n[target]\npanel_lines = 96\npanel_columns = 1024\n",
     ["not enough memory"]),
    ("fuse huge images", ["fuse", "{d}/huge.npy", "{d}/huge.npy"], "", ["not enough memory", "46000"]),
]


@pytest.mark.parametrize(("args", "extra", "needles"), [c[1:] for c in HUGE], ids=[c[0] for c in HUGE])
def test_runs_that_cannot_fit_are_refused_up_front(
    tmp_path: Path, args: list[str], extra: str, needles: list[str]
) -> None:
    cfg = _inputs(tmp_path, extra)
    if "{d}/huge.npy" in args:
        _huge_npy(tmp_path)
    args = [a.replace("{cfg}", str(cfg)).replace("{d}", str(tmp_path)) for a in args]
    args += [*STAGES.get(args[0], []), "--out", str(tmp_path / ("o.exr" if args[0] == "fuse" else "out"))]
    before = _files(tmp_path)
    r = runner.invoke(app, args)
    assert_refused(r, tmp_path, before, *needles)


@pytest.mark.parametrize("command", ["render", "simulate", "ptc", "reproduce", "fuse", "sweep", "dataset"])
@pytest.mark.parametrize("kind", ["memory", "disk"])
def test_every_command_checks_memory_and_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str, kind: str
) -> None:
    """With 1 MiB of memory (or of free disk) left, every command refuses before computing."""
    cfg = _inputs(tmp_path, REPRODUCIBLE)
    if kind == "memory":
        monkeypatch.setattr(resources, "available_memory_bytes", lambda: (1 << 20, "test"))
    else:
        full = shutil.disk_usage(tmp_path)._replace(free=0)  # a full disk
        monkeypatch.setattr(shutil, "disk_usage", lambda path: full)
    args = _command_args(command, tmp_path, cfg)
    before = _files(tmp_path)
    r = runner.invoke(app, args)
    if kind == "memory":
        assert_refused(r, tmp_path, before, "not enough memory", "is available (test)")
    else:
        assert_refused(r, tmp_path, before, "--out = ", "needs about", "but its file system has 0 B free")


# ------------------------------------------------------------------ images for fuse
def _npy(name: str, arr: np.ndarray) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        np.save(folder / name, arr)
        return folder / name

    return make


def _truncated_npy(folder: Path) -> Path:
    np.save(folder / "cut.npy", np.zeros((64, 64), np.uint16))
    data = (folder / "cut.npy").read_bytes()
    (folder / "cut.npy").write_bytes(data[: len(data) // 2])
    return folder / "cut.npy"


def _rgb_png(folder: Path) -> Path:
    from PIL import Image

    Image.fromarray(np.zeros((4, 5, 3), np.uint8)).save(folder / "rgb.png")
    return folder / "rgb.png"


def _pickle_npy(folder: Path) -> Path:
    np.save(folder / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    return folder / "obj.npy"


def _png_claiming(width: int, height: int) -> Callable[[Path], Path]:
    """A PNG whose IHDR claims ``width`` x ``height`` pixels (and holds almost nothing)."""

    def make(folder: Path) -> Path:
        def chunk(kind: bytes, data: bytes) -> bytes:
            return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

        ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
        path = folder / "claims.png"
        idat = chunk(b"IDAT", zlib.compress(b"\0" * 9))
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + idat + chunk(b"IEND", b""))
        return path

    return make


def _fifo(folder: Path) -> Path:
    os.mkfifo(folder / "pipe.npy")
    return folder / "pipe.npy"


BAD_IMAGES: list[tuple[str, Callable[[Path], Path], list[str]]] = [
    # the pedestal's provenance opened the PNG before the image checks: Pillow's own error, exit 1
    ("png claiming 10^10 pixels", _png_claiming(100_000, 100_000), ["claims.png", "10000000000 pixels"]),
    ("png claiming 0 pixels", _png_claiming(0, 5), ["claims.png", "empty image (0 x 5 pixels)"]),
    ("fifo", _fifo, ["pipe.npy", "is a special file (a FIFO (named pipe))"]),
    ("device", lambda f: Path("/dev/zero"), ["/dev/zero", "is a special file (a character device)"]),
    ("truncated npy", _truncated_npy, ["cut.npy"]),
    ("rgb png", _rgb_png, ["rgb.png", "shape (4, 5, 3)"]),
    ("object npy", _pickle_npy, ["obj.npy"]),
    ("complex npy", _npy("c.npy", np.zeros((4, 5), np.complex64)), ["c.npy", "complex64"]),
    ("bool npy", _npy("b.npy", np.zeros((4, 5), bool)), ["b.npy"]),
    ("empty file", _write("e.tif", b""), ["e.tif"]),
    ("gif suffix", _write("x.gif", b"GIF89a"), ["x.gif", "unsupported"]),
    ("truncated jpeg", _write("x.jpg", b"\xff\xd8\xff"), ["x.jpg", "cannot read its header"]),
    ("folder", lambda f: (f / "d.npy").mkdir() or f / "d.npy", ["d.npy"]),
]


@pytest.mark.parametrize(("make", "needles"), [c[1:] for c in BAD_IMAGES], ids=[c[0] for c in BAD_IMAGES])
def test_bad_fuse_images(tmp_path: Path, make: Callable[[Path], Path], needles: list[str]) -> None:
    _inputs(tmp_path)
    bad = make(tmp_path)
    before = _files(tmp_path)
    r = runner.invoke(app, ["fuse", str(tmp_path / "low.npy"), str(bad), "--out", str(tmp_path / "o.exr")])
    assert_refused(r, tmp_path, before, *needles)


@pytest.mark.parametrize("shape", [(0, 0), (0, 8), (8, 0)])
def test_mtf_of_an_empty_image_is_one_line(tmp_path: Path, shape: tuple[int, int]) -> None:
    """An empty image (0 x 0: a ValueError of numpy's reductions before, exit status 1)."""
    np.save(tmp_path / "empty.npy", np.zeros(shape, np.uint16))
    before = _files(tmp_path)
    r = runner.invoke(app, ["mtf", str(tmp_path / "empty.npy"), "--out", str(tmp_path / "m")])
    assert_refused(r, tmp_path, before, "empty.npy", "empty image")


# ------------------------------------------------------------------ environment
@pytest.fixture
def no_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    """A machine without a working CUDA device (whatever this one has), backend not yet chosen."""
    monkeypatch.setattr(backend, "_ACTIVE", None)
    monkeypatch.setattr(backend, "probe_cuda", lambda **kw: ProbeResult(False, "no NVIDIA device (test)"))


def _no_llvm(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(backend, "llvm_candidates", lambda extra=(): [])


ENVIRONMENTS: list[tuple[str, dict[str, str], str, Any, list[str]]] = [
    ("variant garbage", {"BENCH_SIM_VARIANT": "llvm_garbage"}, "", None, ["VARIANT = 'llvm_garbage'"]),
    ("variant vulkan", {"BENCH_SIM_VARIANT": "vulkan"}, "", None, ["BENCH_SIM_VARIANT = 'vulkan'"]),
    ("variant wrong mode", {"BENCH_SIM_VARIANT": "llvm_ad_spectral"}, "", None, ["llvm_ad_spectral", "mono"]),
    ("forced cuda", {"BENCH_SIM_VARIANT": "cuda"}, "", None, ["BENCH_SIM_VARIANT = 'cuda'", "cannot run"]),
    ("forced cuda variant", {"BENCH_SIM_VARIANT": "cuda_ad_mono"}, "", None, ["cuda_ad_mono", "cannot run"]),
    ("config forces cuda", {}, "[render]\nvariant = 'cuda'\n", None, ["variant = 'cuda'", "cannot run"]),
    ("forced llvm, none works", {"BENCH_SIM_VARIANT": "llvm"}, "", _no_llvm, ["'llvm'", "no libLLVM"]),
]


@pytest.mark.parametrize("command", ["render", "simulate", "sweep", "dataset"])
@pytest.mark.parametrize(
    ("env", "extra", "setup", "needles"), [c[1:] for c in ENVIRONMENTS], ids=[c[0] for c in ENVIRONMENTS]
)
def test_forced_variants_that_cannot_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_cuda: None, command: str, env: dict[str, str],
    extra: str, setup: Any, needles: list[str],
) -> None:
    cfg = _inputs(tmp_path, extra)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    if setup is not None:
        setup(monkeypatch)
    before = _files(tmp_path)
    r = runner.invoke(app, _command_args(command, tmp_path, cfg))
    assert_refused(r, tmp_path, before, *needles)


def test_doctor_refuses_a_forced_variant(monkeypatch: pytest.MonkeyPatch, no_cuda: None) -> None:
    monkeypatch.setenv("BENCH_SIM_VARIANT", "cuda")
    r = runner.invoke(app, ["doctor"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "cannot run here" in r.stderr


def test_debug_shows_the_traceback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``BENCH_SIM_DEBUG=1``: the traceback, then the same line and status."""
    cfg = _cfg(tmp_path, "[sensor]\nrows = 0\n")
    monkeypatch.setenv("BENCH_SIM_DEBUG", "1")
    r = runner.invoke(app, ["render", str(cfg), "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "Traceback" in r.stderr
    assert r.stderr.splitlines()[-1].startswith("bench-sim: error: ") and "sensor.rows = 0" in r.stderr
    assert not (tmp_path / "out").exists()


def test_a_bug_is_one_line_with_status_1(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An exception that is not the user's is named in one line (exit 1), no traceback."""
    import bench_sim.workflows.render_job as job

    def broken(*args: Any, **kwargs: Any) -> None:
        raise ZeroDivisionError("division by zero somewhere deep")

    monkeypatch.setattr(job, "run_render", broken)
    r = runner.invoke(app, ["render", str(_inputs(tmp_path)), "--out", str(tmp_path / "out")])
    assert r.exit_code == 1 and r.stderr.count("\n") == 1, r.stderr
    assert "internal error: ZeroDivisionError" in r.stderr and "BENCH_SIM_DEBUG=1" in r.stderr
    assert "Traceback" not in r.stderr


def test_odd_but_legal_configs_warn_with_numbers_and_run(tmp_path: Path) -> None:
    """A word narrower than one pixel's range: one warning line with the numbers, exit 0."""
    cfg = _inputs(tmp_path, "[dtdi]\nbeta_bits = 8\n")
    r = runner.invoke(app, ["render", str(cfg), "--frames", "2", "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.stderr
    warn = [ln for ln in r.stderr.splitlines() if ln.startswith("bench-sim: warning: ")]
    assert len(warn) == 1 and "beta_bits = 8" in warn[0] and "191 DN" in warn[0] and "972 DN" in warn[0]
    assert (tmp_path / "out" / "exposures.exr").is_file()



def test_ctrl_c_inside_c_code_is_an_interruption(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C while a C extension imports comes back as ``SystemError`` from the
    ``KeyboardInterrupt``: still one line and exit status 130."""
    import bench_sim.workflows.render_job as job

    def interrupted(*args: Any, **kwargs: Any) -> None:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            msg = "<built-in function __import__> returned a result with an exception set"
            raise SystemError(msg) from exc

    monkeypatch.setattr(job, "run_render", interrupted)
    r = runner.invoke(app, ["render", str(_inputs(tmp_path)), "--out", str(tmp_path / "out")])
    assert r.exit_code == 130 and r.stderr.count("\n") == 1
    assert r.stderr.startswith("bench-sim: interrupted: ")
