"""Never delete what is not ours: every command on a folder of someone else's files (with a
``points/`` and a ``samples/`` subfolder, the names our journals use) is refused in one line and
leaves every file as it was (``design``, ``ptc --area``, ``calibrate`` of images and ``mtf`` of a
photograph too); ``--resume`` of a sweep (a design) whose ``sweep.json`` (``design.json``) was
lost keeps every finished record; a point record of another spec is never overwritten; a lock
path planted as a link is refused and its target unchanged.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.io import OUTPUT_MARKER, write_frames_npz
from bench_sim.io.folder_lock import lock_path
from tests.metrics.test_sfr import edge_image
from tests.test_bad_inputs import _inputs
from tests.workflows.test_calibrate import _csv, _rows

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()

def _digest(folder: Path) -> dict[str, str]:
    """Every entry below ``folder`` -> the SHA-256 of its bytes (folders: ``dir``)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        out[rel] = "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _users_folder(folder: Path) -> Path:
    """A user's folder: a thesis, results, and subfolders named as our journals are."""
    folder.mkdir()
    (folder / "thesis.tex").write_text("\\chapter{precious}")
    (folder / "results").mkdir()
    (folder / "results" / "fit.csv").write_text("a,b\n1,2\n")
    (folder / "points").mkdir()
    (folder / "points" / "000000.json").write_text('{"mine": true}')
    (folder / "samples").mkdir()
    (folder / "samples" / "notes.txt").write_text("not a record")
    return folder


#: a design of the tiny bench: one point, eq. 11 (the spec of tests/workflows/test_design_resume.py, smaller)
DESIGN = ("base = 'tiny.toml'\nseed = 1\nrules = ['eq11']\nchain_dr = 'chosen'\n"
          "objectives = ['dr_db', 'truth_rms']\n")


def _frames_npz(path: Path) -> Path:
    """A small frames file (three lit levels of two 8 x 8 images, their darks)."""
    rng = np.random.default_rng(0)
    flats = rng.poisson(np.array([50.0, 100.0, 200.0])[:, None, None, None], (3, 2, 8, 8)) + 10.0
    write_frames_npz(path, {"exposure_s": [1e-3] * 3, "photons_per_pixel": [100.0, 200.0, 400.0],
                            "flats": flats, "darks": rng.poisson(10.0, (3, 2, 8, 8)).astype(float)})
    return path


def _photo(path: Path) -> Path:
    """A slanted edge as an 8-bit grey PNG (a photograph)."""
    from PIL import Image

    Image.fromarray(np.clip(edge_image((64, 48), 5.0, sigma=0.8) / 4, 0, 255).astype(np.uint8)).save(path)
    return path


def _command(name: str, tmp: Path, out: Path) -> list[str]:
    cfg = _inputs(tmp, "lines = 600\n[target]\npanel_lines = 256\n" if name == "reproduce" else "")
    if name == "calibrate":
        return ["calibrate", str(_csv(tmp / "ptc.csv", _rows())), "--out", str(out)]
    if name == "calibrate-images":
        return ["calibrate", str(_frames_npz(tmp / "frames.npz")), "--out", str(out)]
    if name == "mtf":
        np.save(tmp / "edge.npy", edge_image((64, 48), 5.0, sigma=0.8))
        return ["mtf", str(tmp / "edge.npy"), "--out", str(out)]
    if name == "mtf-photo":
        return ["mtf", str(_photo(tmp / "edge.png")), "--out", str(out)]
    if name == "ptc-area":
        return ["ptc", str(cfg), "--area", "--out", str(out)]
    if name == "design":
        (tmp / "design.toml").write_text(DESIGN)
        return ["design", str(tmp / "design.toml"), "--out", str(out), "--workers", "0"]
    if name == "export-point":
        return ["sweep", str(tmp / "sweep.toml"), "--export-point", "0", str(out)]
    if name == "init":
        return ["init", str(out)]
    if name in ("sweep", "dataset"):
        return [name, str(tmp / f"{name}.toml"), "--out", str(out), "--workers", "0"]
    stages = {"simulate": ["--stages", "2,8"], "ptc": ["--stages", "1,2"]}.get(name, [])
    return [name, str(cfg), *stages, "--out", str(out)]


COMMANDS = ["render", "simulate", "reproduce", "ptc", "ptc-area", "calibrate", "calibrate-images", "mtf",
            "mtf-photo", "init", "export-point", "sweep", "dataset", "design"]


CASES = [(c, False) for c in COMMANDS] + [("sweep", True), ("dataset", True), ("design", True)]


@pytest.mark.parametrize(("command", "resume"), CASES, ids=[c + (" --resume" if r else "") for c, r in CASES])
def test_a_users_folder_is_refused_by_every_command(tmp_path: Path, command: str, resume: bool) -> None:
    """A folder holding ``thesis.tex``, ``results/``, ``points/`` and ``samples/``: one line,
    exit 2, every file byte for byte as it was."""
    out = _users_folder(tmp_path / "mine")
    args = _command(command, tmp_path, out) + (["--resume"] if resume else [])
    before = _digest(out)
    res = runner.invoke(app, args)
    lines = res.stderr.splitlines()
    assert res.exit_code == 2, (res.exit_code, res.stdout[-400:], res.stderr[-800:])
    assert len(lines) == 1 and lines[0].startswith("bench-sim: error: ") and str(out) in lines[0], lines
    assert _digest(out) == before
    assert not lock_path(out).exists()


def test_sweep_resume_on_a_users_folder_in_a_real_process(tmp_path: Path) -> None:
    """The data loss of 0.3.0 as a user met it: ``sweep --resume`` on a folder with a ``points/``
    subfolder, in a real process: refused, nothing removed."""
    _inputs(tmp_path)
    out = _users_folder(tmp_path / "mine")
    before = _digest(out)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "BENCH_SIM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "bench_sim", "sweep", str(tmp_path / "sweep.toml"), "--out",
                          str(out), "--resume", "--workers", "0"], env=env, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 2, res.stderr
    assert "thesis.tex" in res.stderr or "results" in res.stderr
    assert _digest(out) == before


def _sweep(tmp: Path, out: Path, *extra: str) -> CliRunner:
    res = runner.invoke(app, ["sweep", str(tmp / "sweep.toml"), "--out", str(out), "--workers", "0",
                              "--no-plots", *extra])
    return res


def _records(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((out / "points").glob("*.json"))}


@pytest.mark.slow
def test_resume_after_sweep_json_is_lost_keeps_every_finished_record(tmp_path: Path) -> None:
    """A finished sweep loses ``sweep.json`` and its completion record: ``--resume`` rebuilds
    them from the records, runs nothing again, keeps every record byte for byte, and gives the
    same points as before."""
    _inputs(tmp_path)
    out = tmp_path / "sw"
    assert _sweep(tmp_path, out).exit_code == 0
    records, table = _records(out), (out / "points.csv").read_text()
    assert len(records) == 2
    (out / "sweep.json").unlink()
    (out / OUTPUT_MARKER).unlink()
    res = _sweep(tmp_path, out, "--resume")
    assert res.exit_code == 0, res.stderr
    assert "0 run, 2 skipped" in res.stdout and "rebuilt from the point records" in res.stderr
    assert _records(out) == records
    assert (out / "points.csv").read_text() == table
    assert json.loads((out / "sweep.json").read_text())["status"] == "complete"
    assert (out / OUTPUT_MARKER).is_file()


@pytest.mark.slow
def test_resume_after_design_json_is_lost_keeps_every_finished_record(tmp_path: Path) -> None:
    """A finished design loses ``design.json`` and its completion record: ``--resume`` keeps
    every point record and its scores byte for byte, computes no point again and gives the same
    candidates."""
    _inputs(tmp_path)
    out = tmp_path / "de"
    args = _command("design", tmp_path, out) + ["--no-plots"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.stderr
    kept = {p.name: p.read_bytes() for p in sorted((out / "points").iterdir())}
    table = (out / "candidates.csv").read_text()
    assert len(kept) == 2  # the record and its scores
    (out / "design.json").unlink()
    (out / OUTPUT_MARKER).unlink()
    res = runner.invoke(app, [*args, "--resume"])
    assert res.exit_code == 0, res.stderr
    assert {p.name: p.read_bytes() for p in sorted((out / "points").iterdir())} == kept
    assert (out / "candidates.csv").read_text() == table
    sessions = json.loads((out / "design.json").read_text())["sessions"]
    assert sessions[-1]["ran"] == [] and sessions[-1]["skipped"] == 1
    assert (out / OUTPUT_MARKER).is_file()


@pytest.mark.slow
def test_a_record_of_another_spec_is_never_overwritten(tmp_path: Path) -> None:
    """``--resume`` on a sweep folder holding a record of another seed: refused, the record kept."""
    _inputs(tmp_path)
    out = tmp_path / "sw"
    assert _sweep(tmp_path, out).exit_code == 0
    (out / OUTPUT_MARKER).unlink()
    rec = out / "points" / "000001.json"
    rec.write_text(json.dumps({**json.loads(rec.read_text()), "seed": 99}))
    before = _digest(out)
    res = _sweep(tmp_path, out, "--resume")
    assert res.exit_code == 2 and "points/000001.json is a point record of another spec or seed" in res.stderr
    assert _digest(out) == before


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sweep", "dataset"])
def test_a_finished_run_with_a_users_file_added_is_not_replaced(tmp_path: Path, command: str) -> None:
    """A finished sweep (dataset) into whose folder a user put a file: a rerun without
    ``--resume`` (which would replace it) is refused naming the file; the folder is untouched."""
    _inputs(tmp_path)
    out = tmp_path / "run"
    args = [command, str(tmp_path / f"{command}.toml"), "--out", str(out), "--workers", "0"]
    assert runner.invoke(app, args).exit_code == 0
    (out / "my_notes.md").write_text("precious")
    before = _digest(out)
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "my_notes.md" in res.stderr, res.stderr
    assert _digest(out) == before
    (out / "my_notes.md").unlink()
    assert runner.invoke(app, args).exit_code == 0  # wholly ours again: replaced


@pytest.mark.parametrize("target_kind", ["file", "fifo"])
def test_a_lock_path_planted_as_a_link_or_fifo_is_refused(tmp_path: Path, target_kind: str) -> None:
    """``.NAME.lock`` a symbolic link to a user's file (or a FIFO): refused in one line, the file
    unchanged (not truncated, not written)."""
    _inputs(tmp_path)
    out = tmp_path / "sw"
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    if target_kind == "file":
        lock_path(out).symlink_to(victim)
    else:
        os.mkfifo(lock_path(out))
    res = _sweep(tmp_path, out)
    assert res.exit_code == 2 and "lock file" in res.stderr and len(res.stderr.splitlines()) == 1, res.stderr
    assert victim.read_text() == "precious"
    assert not out.exists()


@pytest.mark.parametrize("option", ["--out", "--tra"])
def test_fuse_never_overwrites_a_file_it_did_not_write(tmp_path: Path, option: str) -> None:
    """An existing ``--out`` EXR (``--tra`` PNG) without bench_sim's provenance is refused and
    kept byte for byte; one that ``fuse`` wrote itself is replaced by a rerun."""
    _inputs(tmp_path)
    name = "hdr.exr" if option == "--out" else "tra.png"
    theirs = tmp_path / name
    theirs.write_bytes(b"someone's image")
    args = ["fuse", str(tmp_path / "low.npy"), str(tmp_path / "high.npy"), "--out", str(tmp_path / "hdr.exr"),
            "--tra", str(tmp_path / "tra.png")]
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and option in res.stderr, res.stderr
    assert "not written by bench_sim" in res.stderr
    assert theirs.read_bytes() == b"someone's image"
    theirs.unlink()
    assert runner.invoke(app, args).exit_code == 0
    assert runner.invoke(app, args).exit_code == 0  # ours now: replaced
