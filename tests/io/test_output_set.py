"""Outputs are written as a set: all files or none, a rerun replaces the whole set, temporaries
of killed runs are removed, write failures are one line (``bench_sim.io``)."""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

import pytest

from bench_sim import io as bio
from bench_sim.errors import BenchSimError
from bench_sim.io import (
    OUTPUT_MARKER,
    OutputWriteError,
    atomic,
    output_files,
    output_set,
    outputs,
    read_output_record,
    umask,
)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _write_set(out: Path, files: dict[str, str], record: dict | None = None) -> None:
    with output_set(out, record or {"command": "test"}) as tmp:
        for name, text in files.items():
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            bio.write_text(tmp / name, text)


def _temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".partial-" in p.name or ".old-" in p.name)


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2 exchange", "two renames"])
def test_a_rerun_replaces_the_whole_set(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool
) -> None:
    if not exchange:
        monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)  # what output_set calls
    out = tmp_path / "out"
    _write_set(out, {"ground_truth.exr": "1", "stage_001/a.tif": "1", "meta.json": "1"}, {"seed": 1})
    _write_set(out, {"meta.json": "2", "stage_002/a.tif": "2"}, {"seed": 2})
    assert set(_tree(out)) == {"meta.json", "stage_002/a.tif", OUTPUT_MARKER}  # nothing of run 1 left
    assert read_output_record(out) == {"seed": 2, "files": ["meta.json", "stage_002/a.tif"]}
    assert _temporaries(tmp_path) == []
    assert oct(out.stat().st_mode & 0o777) == oct(0o777 & ~umask())


@pytest.mark.parametrize(
    ("error", "seen"),
    [
        (KeyboardInterrupt(), KeyboardInterrupt),
        (ValueError("a bug"), ValueError),
        (OSError(errno.ENOSPC, "No space left on device"), OutputWriteError),
    ],
)
def test_a_failed_run_keeps_the_previous_set(tmp_path: Path, error: BaseException, seen: type) -> None:
    out = tmp_path / "out"
    _write_set(out, {"a.txt": "old", "b.txt": "old"})
    before = _tree(out)
    with pytest.raises(seen), output_set(out) as tmp:
        bio.write_text(tmp / "a.txt", "new")
        raise error
    assert _tree(out) == before and _temporaries(tmp_path) == []


def test_a_failed_first_run_leaves_nothing(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), output_set(tmp_path / "out") as tmp:
        bio.write_text(tmp / "a.txt", "x")
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_only_empty_or_bench_sim_folders_are_replaced(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    _write_set(tmp_path / "empty", {"a.txt": "x"})
    (tmp_path / "thesis").mkdir()
    (tmp_path / "thesis" / "chapter1.tex").write_text("precious")
    with pytest.raises(BenchSimError, match="not written by bench_sim"):
        _write_set(tmp_path / "thesis", {"a.txt": "x"})
    assert (tmp_path / "thesis" / "chapter1.tex").read_text() == "precious"


def _dead_pid() -> int:
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        os._exit(0)
    os.waitpid(pid, 0)
    return pid


def test_temporaries_of_dead_runs_are_removed_and_live_ones_kept(tmp_path: Path) -> None:
    out = tmp_path / "out"
    dead = Path(tempfile.mkdtemp(prefix=f".out.partial-{_dead_pid()}-", dir=tmp_path))
    (dead / "exposures.exr").write_bytes(b"x" * 1000)
    dead_file = Path(tempfile.mkstemp(prefix=f".out.partial-{_dead_pid()}-", dir=tmp_path)[1])
    live = Path(tempfile.mkdtemp(prefix=f".out.partial-{os.getpid()}-", dir=tmp_path))
    fd = os.open(live, os.O_RDONLY)
    atomic._lock(fd)  # a run that is still writing holds the lock
    try:
        _write_set(out, {"a.txt": "x"})
        assert not dead.exists() and not dead_file.exists() and live.is_dir()
    finally:
        os.close(fd)
    os.utime(live, (0, 0))  # unlocked, and its process (this one) has had it for ages: stale
    _write_set(out, {"a.txt": "y"})
    assert not live.exists() and _temporaries(tmp_path) == []


def test_a_set_moved_aside_by_a_killed_run_is_put_back(tmp_path: Path) -> None:
    """Killed between its two renames (file systems without an atomic exchange): the previous
    set waits in ``.out.old-PID-*/set`` and ``out`` is missing; the next run restores it first."""
    out = tmp_path / "out"
    _write_set(out, {"a.txt": "old"})
    old = Path(tempfile.mkdtemp(prefix=f".out.old-{_dead_pid()}-", dir=tmp_path))
    os.replace(out, old / "set")
    atomic._remove_stale_temporaries(out)
    assert (out / "a.txt").read_text() == "old" and _temporaries(tmp_path) == []


def test_output_files_are_written_together_or_not_at_all(tmp_path: Path) -> None:
    a, b = tmp_path / "hdr.exr", tmp_path / "sub" / "tra.png"
    with pytest.raises(OutputWriteError, match="No space left on device"), output_files([a, b]) as (ta, tb):
        ta.write_bytes(b"hdr")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert not a.exists() and not b.exists()
    assert [p.name for p in tmp_path.rglob("*") if p.is_file()] == []
    with output_files([a, b]) as (ta, tb):
        ta.write_bytes(b"hdr")
        tb.write_bytes(b"png")
    assert a.read_bytes() == b"hdr" and b.read_bytes() == b"png"


@pytest.mark.parametrize(
    ("exc", "needle"),
    [
        (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "x.exr"), "No space left on device (ENOSPC)"),
        (OSError(errno.EDQUOT, os.strerror(errno.EDQUOT)), "(EDQUOT)"),
        (OSError(errno.EFBIG, os.strerror(errno.EFBIG)), "File too large (EFBIG)"),
        (OSError(errno.EROFS, os.strerror(errno.EROFS)), "Read-only file system (EROFS)"),
        (OSError(errno.EACCES, os.strerror(errno.EACCES)), "Permission denied (EACCES)"),
        (OSError("1000000 requested and 24932 written"), "requested and 24932 written"),  # tifffile
        (RuntimeError('Failed to write pixel data to image file "x.exr". File too large.'), "File too large"),
        (RuntimeError("NetCDF: HDF error"), "HDF error"),  # netCDF4 on a full disk
    ],
)
def test_write_failures_become_one_line(tmp_path: Path, exc: Exception, needle: str) -> None:
    err = bio.write_failure(exc, tmp_path / "out")
    assert isinstance(err, OutputWriteError) and needle in str(err) and "\n" not in str(err)
    assert str(err).startswith(f"--out = '{tmp_path / 'out'}': cannot write the output")


@pytest.mark.parametrize("exc", [RuntimeError("boom"), ValueError("x"), KeyboardInterrupt(), BenchSimError()])
def test_other_errors_are_not_write_failures(tmp_path: Path, exc: BaseException) -> None:
    assert bio.write_failure(exc, tmp_path) is None


def test_atomic_exchange_swaps_two_folders(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "x").write_text("a")
    (b / "x").write_text("b")
    if outputs._exchange(a, b):  # Linux with renameat2 (every CI machine of this project)
        assert (a / "x").read_text() == "b" and (b / "x").read_text() == "a"
    else:  # pragma: no cover - other systems: the two-rename path is tested above
        assert (a / "x").read_text() == "a"


def test_a_folder_without_a_file_list_is_never_replaced(tmp_path: Path) -> None:
    """Only what a record lists is ours: an output of bench_sim 0.1 (provenance in metrics.json,
    no record) and of 0.3 (a record without ``files``) are refused, their files untouched."""
    legacy = tmp_path / "paper"
    legacy.mkdir()
    (legacy / "metrics.json").write_text('{"version": "0.1.0", "config_sha256": "ab", "seed": 0}')
    with pytest.raises(BenchSimError, match="not written by bench_sim"):
        _write_set(legacy, {"metrics.json": "{}"})
    v03 = tmp_path / "v03"
    v03.mkdir()
    (v03 / OUTPUT_MARKER).write_text('{"command": "reproduce", "version": "0.3.0"}')
    (v03 / "fig3_stages.png").write_bytes(b"png")
    with pytest.raises(BenchSimError, match="older bench_sim whose record does not list its files"):
        _write_set(v03, {"a.txt": "x"})
    assert (v03 / "fig3_stages.png").read_bytes() == b"png" and (legacy / "metrics.json").is_file()


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2 exchange", "two renames"])
def test_a_file_added_to_a_set_keeps_the_set_from_being_replaced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exchange: bool
) -> None:
    """A user's file put into an output folder (or a subfolder of it) makes it not wholly ours:
    the rerun is refused in one line naming the file, which stays."""
    if not exchange:
        monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    out = tmp_path / "out"
    _write_set(out, {"meta.json": "1", "stage_001/a.tif": "1"})
    (out / "stage_001" / "notes.txt").write_text("precious")
    with pytest.raises(BenchSimError, match=r"holds 'stage_001/notes.txt', which bench_sim did not write"):
        _write_set(out, {"meta.json": "2"})
    assert (out / "stage_001" / "notes.txt").read_text() == "precious"
    assert (out / "meta.json").read_text() == "1"


def test_a_file_added_during_the_run_is_kept(tmp_path: Path) -> None:
    """The folder is checked again when the new set is put in place: an entry that appeared in
    it while the run worked is not removed (the run is refused, the previous set stays)."""
    out = tmp_path / "out"
    _write_set(out, {"meta.json": "1"})
    with pytest.raises(BenchSimError, match="draft.md"), output_set(out, {"command": "test"}) as tmp:
        bio.write_text(tmp / "meta.json", "2")
        (out / "draft.md").write_text("written meanwhile")
    assert (out / "draft.md").read_text() == "written meanwhile" and (out / "meta.json").read_text() == "1"
    assert _temporaries(tmp_path) == []


def test_a_step_still_writing_after_the_set_is_removed_does_not_make_it_again(tmp_path: Path) -> None:
    """A pool's worker writing a file of an interrupted run (its set's temporary folder already
    removed) fails instead of making the folder again and leaving it behind (a leftover
    ``.run.partial-...`` after a SIGTERM in the stress series); other missing folders are made."""
    import threading

    out = tmp_path / "run"
    started, removed = threading.Event(), threading.Event()
    errors: list[BaseException] = []

    def late_writer(folder: Path) -> None:
        started.set()
        removed.wait(10)
        try:
            bio.write_text(folder / "images" / "late.txt", "x")
        except BaseException as exc:  # noqa: BLE001 - what the writer saw
            errors.append(exc)

    with pytest.raises(KeyboardInterrupt), output_set(out, {"command": "test"}) as tmp:
        worker = threading.Thread(target=late_writer, args=(tmp,))
        worker.start()
        started.wait(10)
        raise KeyboardInterrupt
    removed.set()
    worker.join(10)
    assert errors and "removed" in str(errors[0]), errors
    assert _temporaries(tmp_path) == [] and not out.exists()
    bio.write_text(tmp_path / "new" / "deep" / "f.txt", "y")
    assert (tmp_path / "new" / "deep" / "f.txt").read_text() == "y"
