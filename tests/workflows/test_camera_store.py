"""The sweep's camera columns on disk (:mod:`bench_sim.workflows.sweep.camera_store`): the
columns read back bit for bit, a stored camera is not measured again and gives what a
measurement gives, the key changes with everything the measurement depends on (and not with
the lights), and a bad file, other versions or the switch turned off are misses."""

from __future__ import annotations

import struct

import pytest

from bench_sim.measure import chain_dr
from bench_sim.render import record_store
from bench_sim.workflows.sweep import camera_store, point
from tests.conftest import tiny_cfg

LEVELS = 8


@pytest.fixture
def store(disk_stores):
    """The stores turned on in a fresh cache folder; the camera columns' folder."""
    folder = camera_store.store_dir()
    assert folder == disk_stores / "camera_dr"
    return folder


def _bits(columns: dict) -> dict:
    """Each column as its type and exact bits (floats by their IEEE 754 bytes)."""
    return {k: (type(v), struct.pack("<d", v) if isinstance(v, float) else v) for k, v in columns.items()}


def test_columns_read_back_bit_for_bit(store):
    columns = {"a": 0.1 + 0.2, "b": -0.0, "c": 5e-324, "d": 1.7976931348623157e308, "e": True,
               "f": None, "g": 20.0 * 0.30102999566398120, "h": 3}
    camera_store.save("cam", columns)
    got = camera_store.load("cam")
    assert got is not None and _bits(got) == _bits(columns)


def test_a_stored_camera_is_not_measured_again(store, monkeypatch):
    """The first ``camera_dr`` measures and stores; the second loads what the first returned,
    bit for bit, without measuring; with the store off a measurement gives the same columns."""
    cfg = tiny_cfg()
    first = point.camera_dr((cfg, 7, LEVELS))
    assert len(list(store.iterdir())) == 1

    def no_measurement(*_a, **_k):
        raise AssertionError("measured again")

    with monkeypatch.context() as m:
        m.setattr(point, "measure_chain_dynamic_range", no_measurement)
        again = point.camera_dr((cfg, 7, LEVELS))
    assert _bits(again) == _bits(first)
    monkeypatch.setenv(record_store.ENV_SWITCH, "off")
    fresh = point.camera_dr((cfg, 7, LEVELS))
    assert _bits(fresh) == _bits(first)
    assert chain_dr.measure_chain_dynamic_range is point.measure_chain_dynamic_range


@pytest.mark.parametrize(("sections", "seed", "levels"), [
    ({"sensor": {"read_noise_e": 3.0}}, 7, LEVELS),
    ({"timing": {"line_period_s": 2e-4}}, 7, LEVELS),
    ({"dtdi": {"beta_bits": 10}}, 7, LEVELS),
    ({"fusion": {"mu1": 3}}, 7, LEVELS),
    ({"fusion": {"mu2": 6}}, 7, LEVELS),
    ({}, 8, LEVELS),
    ({}, 7, LEVELS + 1),
])
def test_the_key_changes_with_each_input(sections, seed, levels):
    base = point.camera_key(tiny_cfg(), 7, LEVELS)
    assert point.camera_key(tiny_cfg(**sections), seed, levels) != base


def test_the_key_does_not_change_with_the_lights():
    """A light's power is not the camera's (a sweep over it shares one measurement)."""
    cfg = tiny_cfg()
    brighter = tiny_cfg(lights={"strong": {"irradiance_w_m2": 2 * cfg.lights.strong.irradiance_w_m2}})
    assert point.camera_key(brighter, 7, LEVELS) == point.camera_key(cfg, 7, LEVELS)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_a_bad_file_is_a_miss_and_is_removed(store, damage):
    camera_store.save("cam", {"a": 1.0})
    [path] = list(store.iterdir())
    data = path.read_bytes()
    path.write_bytes({"truncate": data[: len(data) // 2], "garbage": b"not a zip" * 50, "empty": b""}[damage])
    assert camera_store.load("cam") is None and not path.exists()


def test_another_key_or_versions_is_a_miss(store, monkeypatch):
    camera_store.save("cam", {"a": 1.0})
    assert camera_store.load("other") is None
    monkeypatch.setitem(camera_store.versions(), "source", "edited")
    assert camera_store.load("cam") is None


def test_turned_off_nothing_is_written_or_read(store, monkeypatch):
    camera_store.save("cam", {"a": 1.0})
    monkeypatch.setenv(record_store.ENV_SWITCH, "off")
    assert camera_store.load("cam") is None
    camera_store.save("cam2", {"a": 1.0})
    assert len(list(store.iterdir())) == 1
