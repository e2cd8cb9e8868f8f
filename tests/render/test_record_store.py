"""The on-disk store of the fast engine's light records (:mod:`bench_sim.render.record_store`):
byte-identical round trips, misses for anything else (other key, other versions, a bad file),
the switch, the size bound, and writes that fail without failing the run."""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path

import numpy as np
import pytest

from bench_sim.render import kernel_store, record_store, records
from bench_sim.render.records import LightRecords
from tests.conftest import tiny_cfg

VARIANT = "llvm_ad_mono"


@pytest.fixture
def store(disk_stores):
    """The store turned on in a fresh cache folder; its records folder."""
    folder = record_store.store_dir()
    assert folder == disk_stores / "records"
    return folder


def _records(key: str = "scene-a", seed: int = 0) -> LightRecords:
    lights = ("strong", "weak")
    rng = np.random.default_rng(seed)
    m, n, ss = 3, 5, 2
    hit = rng.random((m * ss, n * ss)) < 0.8
    position = np.where(hit[..., None], rng.normal(size=(m * ss, n * ss, 3)), 0.0).astype(np.float32)
    return LightRecords(
        lights,
        rng.random((len(lights), m * ss, n * ss), dtype=np.float32),
        rng.random((len(lights), m, n), dtype=np.float32),
        position,
        hit,
        key,
        renders=2,
    )


def _args(rec: LightRecords) -> tuple[str, tuple[str, ...], dict[str, np.ndarray]]:
    """What :func:`record_store.save` takes of a record set."""
    return rec.key, rec.lights, {name: getattr(rec, name) for name in record_store.ARRAYS}


def _same_bytes(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _files(folder: Path) -> list[Path]:
    return sorted(folder.iterdir()) if folder.is_dir() else []


def test_round_trip_is_byte_identical(store):
    rec = _records()
    record_store.save(*_args(rec))
    [path] = _files(store)  # one file, no temporaries left
    assert path.suffix == ".npz" and len(path.stem) == 64
    got = record_store.load(rec.key)
    assert got is not None
    lights, arrays = got
    assert lights == rec.lights and set(arrays) == set(record_store.ARRAYS)
    for name in ("d_rec", "static", "position", "hit"):
        assert _same_bytes(arrays[name], getattr(rec, name)), name


def test_a_stored_set_is_mapped_read_only_and_paged_out_unchanged(store):
    """The arrays of a stored set are read-only views of a memory map of its file, not copies;
    :func:`record_store.page_out` (the engine's, once its kernels are made) lets their pages go
    and they read the same bytes after it, also after the file is deleted (the map holds it)."""
    import mmap

    rec = _records()
    record_store.save(*_args(rec))
    got = record_store.load(rec.key)
    assert got is not None
    arrays = got[1]
    for name, a in arrays.items():
        assert isinstance(a.base, mmap.mmap) and not a.flags.writeable, name
        with pytest.raises(ValueError):
            a.flat[0] = 0
    for path in _files(store):
        path.unlink()
    record_store.page_out(list(arrays.values()))
    for name in record_store.ARRAYS:
        assert _same_bytes(arrays[name], getattr(rec, name)), name
    record_store.page_out([rec.d_rec])  # arrays in memory: left as they are
    assert _same_bytes(rec.d_rec, _records().d_rec)


def test_a_set_from_disk_joins_the_process_cache_with_no_renders(store):
    """``cached_records`` finds a stored set (no Mitsuba needed), as one of 0 renders, and keeps
    it in the process's cache; ``light_records`` returns it as not rendered."""
    cfg = tiny_cfg()
    rec = _records(records.records_key(cfg, VARIANT))
    records.clear_record_cache()
    try:
        assert records.cached_records(cfg, VARIANT) is None
        record_store.save(*_args(rec))
        n0 = records.mitsuba_render_count()
        got = records.cached_records(cfg, VARIANT)
        assert got is not None and got.renders == 0 and _same_bytes(got.d_rec, rec.d_rec)
        for path in _files(store):
            path.unlink()
        assert records.cached_records(cfg, VARIANT) is got  # now from the process's cache
        again, rendered = records.light_records(None, cfg, None, VARIANT)  # type: ignore[arg-type]
        assert again is got and not rendered
        assert records.mitsuba_render_count() == n0
    finally:
        records.clear_record_cache()


def test_another_key_is_a_miss(store):
    rec = _records("scene-a")
    record_store.save(*_args(rec))
    assert record_store.load("scene-b") is None
    # a file of another key under this key's name (never written so): a miss, and removed
    [path] = _files(store)
    wrong = record_store.entry_path(store, "scene-b", record_store.versions())
    path.rename(wrong)
    assert record_store.load("scene-b") is None and not wrong.exists()


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_a_bad_file_is_a_miss_and_is_removed(store, damage):
    rec = _records()
    record_store.save(*_args(rec))
    [path] = _files(store)
    data = path.read_bytes()
    bad = {"truncate": data[: len(data) // 2], "garbage": b"not a zip" * 100, "empty": b""}
    path.write_bytes(bad[damage])
    assert record_store.load(rec.key) is None
    assert not path.exists()
    record_store.save(*_args(rec))  # written again, read again
    assert record_store.load(rec.key) is not None


def test_a_read_error_is_a_miss(store, monkeypatch):
    rec = _records()
    record_store.save(*_args(rec))

    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(record_store.np, "load", denied)
    assert record_store.load(rec.key) is None


def test_other_versions_are_a_miss(store, monkeypatch):
    rec = _records()
    record_store.save(*_args(rec))
    [path] = _files(store)
    current = record_store.versions()
    for what in ("mitsuba", "drjit", "bench_sim", "format", "source"):
        other = {**current, what: current[what] + "-other"}
        monkeypatch.setattr(record_store, "versions", lambda other=other: other)
        assert record_store.load(rec.key) is None, what  # another file name
        assert path.exists()
    # a file of other versions under this name (never written so): a miss, and removed
    record_store.save(*_args(rec))
    monkeypatch.setattr(record_store, "versions", lambda: current)
    newer = [p for p in _files(store) if p != path]
    assert len(newer) == 1
    newer[0].replace(path)
    assert record_store.load(rec.key) is None and not path.exists()


@pytest.mark.parametrize("value", ["off", "0", "false", "no", "OFF", " No "])
def test_turned_off_nothing_is_written_or_read(store, monkeypatch, value):
    rec = _records()
    record_store.save(*_args(rec))
    monkeypatch.setenv(record_store.ENV_SWITCH, value)
    assert record_store.store_dir() is None
    assert record_store.load(rec.key) is None
    record_store.save(*_args(_records("scene-b")))
    monkeypatch.setenv(record_store.ENV_SWITCH, "on")
    assert len(_files(store)) == 1 and record_store.load("scene-b") is None


def test_size_bound_evicts_the_least_recently_used(store, monkeypatch):
    a, b, c = (_records(k, seed=i) for i, k in enumerate("abc"))
    record_store.save(*_args(a))
    size = _files(store)[0].stat().st_size
    monkeypatch.setenv(record_store.ENV_SIZE, str(2.5 * size / 2**20))  # room for two sets
    record_store.save(*_args(b))
    path_a, path_b = (record_store.entry_path(store, k, record_store.versions()) for k in ("a", "b"))
    now = time.time()
    os.utime(path_a, (now - 100, now - 100))
    os.utime(path_b, (now - 50, now - 50))
    assert record_store.load("a") is not None  # touched: now the most recently used
    record_store.save(*_args(c))
    path_c = record_store.entry_path(store, "c", record_store.versions())
    assert sorted(_files(store)) == sorted([path_a, path_c])
    monkeypatch.setenv(record_store.ENV_SIZE, "0")
    record_store.save(*_args(b))
    assert _files(store) == []


@pytest.mark.parametrize("value", ["lots", "-1", "nan", ""])
def test_a_bad_size_bound_means_the_default(monkeypatch, value):
    monkeypatch.setenv(record_store.ENV_SIZE, value)
    assert record_store.limit_bytes() == int(record_store.DEFAULT_MIB * 2**20)


def test_a_folder_that_cannot_be_written_raises_nothing(store, monkeypatch):
    rec = _records()
    store.parent.mkdir(parents=True)
    store.write_text("a file where the folder should be")
    record_store.save(*_args(rec))
    assert record_store.load(rec.key) is None
    store.unlink()

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(record_store.np, "savez", full)
    record_store.save(*_args(rec))  # the disk is full: skipped, its temporary removed
    assert _files(store) == []
    assert record_store.load(rec.key) is None


def test_usage_and_doctor_report_the_store(store, monkeypatch):
    from typer.testing import CliRunner

    from bench_sim import cli
    from bench_sim.runtime.backend import BackendChoice

    assert record_store.usage() == (0, 0)
    record_store.save(*_args(_records("a")))
    record_store.save(*_args(_records("b")))
    size = sum(p.stat().st_size for p in _files(store))
    assert record_store.usage() == (size, 2)
    monkeypatch.setattr(cli, "choose_backend", lambda: BackendChoice("scalar_rgb", "scalar", None, "test"))
    res = CliRunner().invoke(cli.app, ["doctor"])
    assert res.exit_code == 0 and f"record cache: {store} ({size / 2**20:.1f} MiB, 2 sets)" in res.stdout
    # the stores beside it, each with its own folder and size (the kernel store's entry counted)
    kernel_store.save("k", [(0, 0, np.ones((1, 2, 2, 3), np.float32))])
    kernels = kernel_store.store_dir()
    assert kernels is not None and kernels.parent == store.parent
    k_size = sum(p.stat().st_size for p in kernels.iterdir())
    said = CliRunner().invoke(cli.app, ["doctor"]).stdout
    assert f"  kernels   : {kernels} ({k_size / 2**20:.1f} MiB, 1 files)" in said
    assert "  textures  : " in said and "  camera DR : " in said
    monkeypatch.setenv(record_store.ENV_SWITCH, "off")
    assert record_store.usage() == (0, 0)
    assert "record cache: off" in CliRunner().invoke(cli.app, ["doctor"]).stdout


@pytest.mark.slow
def test_a_new_process_reads_the_records_from_disk_without_rendering(store):
    """Records rendered once (and stored), then the process's cache cleared (as in a new
    process): the set-up makes no Mitsuba render, counts 0 renders, and its records and frames
    are byte for byte those rendered."""
    from bench_sim.render.exposures import fast_records, iter_photon_frames, prepare

    cfg = tiny_cfg()

    def frames():
        setup = prepare(cfg, 4, np.random.default_rng(0), engine="fast", first_frame=60)
        return np.concatenate(list(iter_photon_frames(setup))), setup

    records.clear_record_cache()
    try:
        rendered, s0 = frames()
        assert s0.info["mitsuba_renders"] > 0 and len(_files(store)) == 1
        records.clear_record_cache()
        n0 = records.mitsuba_render_count()
        loaded, s1 = frames()
        assert s1.info["mitsuba_renders"] == 0 and records.mitsuba_render_count() == n0
        r0, r1 = s0.engine.records, s1.engine.records
        assert r1.renders == 0 and r1.lights == r0.lights and r1.key == r0.key
        for name in ("d_rec", "static", "position", "hit"):
            assert _same_bytes(getattr(r1, name), getattr(r0, name)), name
        assert _same_bytes(loaded, rendered)
        records.clear_record_cache()
        assert fast_records(cfg).renders == 0 and records.mitsuba_render_count() == n0
    finally:
        records.clear_record_cache()


@pytest.mark.parametrize("on", [True, False])
def test_release_lets_go_of_a_pass_render_state(store, monkeypatch, on):
    """``release`` (``reproduce`` after its pass): the set-up's engine goes; with the stores on,
    the scene's records leave the process's cache and the grid's blocks are dropped (a later
    pass reads them from disk, the same values); with them off both stay (they would have to be
    rendered again)."""
    from bench_sim.render.exposures import prepare, release

    monkeypatch.setenv(record_store.ENV_SWITCH, "on" if on else "off")
    records.clear_record_cache()
    try:
        cfg = tiny_cfg()
        setup = prepare(cfg, 8, np.random.default_rng(0))
        key = setup.engine.records.key
        before = setup.grid.rows(0, 4)
        assert setup.grid.held_bytes > 0 and key in records._cache
        release(setup)
        assert setup.engine is None
        assert (key in records._cache) is not on
        assert (setup.grid.held_bytes == 0) is on
        assert np.array_equal(setup.grid.rows(0, 4), before)
    finally:
        records.clear_record_cache()


def test_a_texture_block_round_trips_as_a_read_only_map(store):
    """:mod:`bench_sim.render.texture_store`: a block stored is loaded as the same bytes, a
    read-only map of its file (no copy); another shape is a miss (and the file is deleted)."""
    import mmap

    from bench_sim.render import texture_store

    values = np.random.default_rng(3).random((7, 11), dtype=np.float32)
    texture_store.save("block-a", values)
    got = texture_store.load("block-a", values.shape)
    assert got is not None and _same_bytes(got, values)
    assert isinstance(got.base, mmap.mmap) and not got.flags.writeable
    assert texture_store.load("block-a", (7, 12)) is None
    assert texture_store.load("block-a", values.shape) is None
