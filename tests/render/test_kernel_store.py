"""The fast engine's row kernels on disk (:mod:`bench_sim.render.kernel_store`): byte-identical
round trips, a key that changes with every input, misses for a bad file or other versions, the
record store's switch, and an engine whose kernels come from the store computing the same
frames as one that derived them."""

from __future__ import annotations

import numpy as np
import pytest

from bench_sim.render import kernel_store, record_store, records
from tests.conftest import tiny_cfg


@pytest.fixture
def store(disk_stores):
    """The stores turned on in a fresh cache folder; the kernels' folder."""
    folder = kernel_store.store_dir()
    assert folder == disk_stores / "kernels"
    return folder


def _kernels(seed: int = 0) -> kernel_store.RowKernels:
    rng = np.random.default_rng(seed)
    return [(int(rng.integers(-50, 50)), int(rng.integers(0, 9)),
             rng.random((2, 1 + i, 3, 5), dtype=np.float32)) for i in range(4)]


def _same(a: kernel_store.RowKernels, b: kernel_store.RowKernels) -> bool:
    return len(a) == len(b) and all(
        (ya, xa) == (yb, xb) and wa.dtype == wb.dtype and wa.shape == wb.shape
        and wa.tobytes() == wb.tobytes()
        for (ya, xa, wa), (yb, xb, wb) in zip(a, b, strict=True)
    )


def test_round_trip_is_byte_identical(store):
    kern = _kernels()
    kernel_store.save("k", kern)
    [path] = list(store.iterdir())  # one file, no temporaries left
    assert path.suffix == ".npz" and len(path.stem) == 64
    got = kernel_store.load("k")
    assert got is not None and _same(got, kern)
    assert all(isinstance(y, int) and isinstance(x, int) for y, x, _ in got)


def test_another_key_or_versions_is_a_miss(store, monkeypatch):
    kernel_store.save("k", _kernels())
    assert kernel_store.load("other") is None
    monkeypatch.setitem(kernel_store.versions(), "engine", "edited")
    assert kernel_store.load("k") is None


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_a_bad_file_is_a_miss_and_is_removed(store, damage):
    kernel_store.save("k", _kernels())
    [path] = list(store.iterdir())
    data = path.read_bytes()
    path.write_bytes({"truncate": data[: len(data) // 2], "garbage": b"not a zip" * 50, "empty": b""}[damage])
    assert kernel_store.load("k") is None and not path.exists()


@pytest.mark.parametrize("member", ["shapes", "weights", "bases"])
def test_members_that_do_not_add_up_are_a_miss_and_are_removed(store, member):
    """The weights' member holds every row's weights back to back: a file whose shapes, weights
    or bases disagree with each other or with its number of rows is not read."""
    kern = _kernels()
    kernel_store.save("k", kern)
    [path] = list(store.iterdir())
    with np.load(path) as z:
        arrays = {name: z[name] for name in z.files if name != "meta"}
    arrays[member] = {"shapes": arrays["shapes"] + 1, "weights": arrays["weights"][:-1],
                      "bases": arrays["bases"][:-1]}[member]
    path.unlink()
    record_store.write_entry(store, "k", kernel_store.versions(), {"rows": len(kern)}, lambda: arrays)
    assert len(list(store.iterdir())) == 1
    assert kernel_store.load("k") is None and not any(store.iterdir())


@pytest.mark.parametrize("value", ["off", "0"])
def test_turned_off_nothing_is_written_or_read(store, monkeypatch, value):
    kernel_store.save("k", _kernels())
    monkeypatch.setenv(record_store.ENV_SWITCH, value)
    assert kernel_store.store_dir() is None and kernel_store.load("k") is None
    kernel_store.save("k2", _kernels())
    assert len(list(store.iterdir())) == 1


def test_a_folder_that_cannot_be_written_raises_nothing(store):
    store.parent.mkdir(parents=True, exist_ok=True)
    store.write_text("a file where the folder should be")
    kernel_store.save("k", _kernels())  # skipped
    assert kernel_store.load("k") is None


def _engine(cfg):
    from bench_sim.render.exposures import prepare

    return prepare(cfg, 4, np.random.default_rng(0), engine="fast").engine


@pytest.mark.parametrize(("section", "change"), [
    ("sensor", {"rows": 10}), ("sensor", {"columns": 40}), ("render", {"subpixels": 3}),
    ("drum", {"radius_m": 0.09}),
])
def test_the_key_changes_with_each_input(store, section, change):
    """The records' key, the grid's (its texel sizes and start, the drum's offset and radius)
    and the sensor's rows, columns and sub-pixels are each part of the kernels' key."""
    records.clear_record_cache()
    try:
        engine = _engine(tiny_cfg())
        grid_key = ("kernels", 2, 1e-5, 2e-5, -0.01, 0.0, 0.05)
        key = engine.kernel_key(grid_key)
        for i in range(1, len(grid_key)):  # each of the grid's numbers, by its exact value
            changed = (*grid_key[:i], np.nextafter(float(grid_key[i]), np.inf), *grid_key[i + 1:])
            assert engine.kernel_key(changed) != key
        other = _engine(tiny_cfg(**{section: change}))
        assert other.kernel_key(grid_key) != key
    finally:
        records.clear_record_cache()


def test_kernels_from_the_store_give_the_same_frames(store):
    """A first engine derives the kernels and stores them; after the process's caches are
    cleared (a new process) a second one loads them: the same kernels byte for byte, and the
    same frames."""
    from bench_sim.render.exposures import iter_photon_frames, prepare

    cfg = tiny_cfg()

    def run():
        setup = prepare(cfg, 4, np.random.default_rng(0), engine="fast", first_frame=60)
        return np.concatenate(list(iter_photon_frames(setup))), setup.engine

    records.clear_record_cache()
    try:
        f0, e0 = run()
        assert len(list(store.iterdir())) == 1
        records.clear_record_cache()
        calls = []
        derive = type(e0)._kernels
        type(e0)._kernels = lambda self: calls.append(1) or derive(self)  # type: ignore[method-assign]
        try:
            f1, e1 = run()
        finally:
            type(e0)._kernels = derive  # type: ignore[method-assign]
        assert calls == []  # loaded, not derived
        mine = [(k.base_y, k.base_x, k.weights) for k in e1.kernels]
        assert _same(mine, [(k.base_y, k.base_x, k.weights) for k in e0.kernels])
        assert f1.dtype == f0.dtype and f1.tobytes() == f0.tobytes()
    finally:
        records.clear_record_cache()
