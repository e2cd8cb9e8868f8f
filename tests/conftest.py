"""Shared fixtures: tiny benches built from the default rig by overriding a few keys."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from bench_sim.config import BenchConfig, load_config, with_overrides
from bench_sim.render import record_store

# a skip fails the session unless listed in tests/allowed_skips.txt (--strict-skips, or CI set)
from tests.skip_guard import (  # noqa: F401 - pytest's hooks, found by name
    pytest_addoption,
    pytest_configure,
    pytest_make_collect_report,
    pytest_runtest_makereport,
)

#: pytest's own plugin for running pytest on generated test files (tests/test_skip_guard.py)
pytest_plugins = ["pytester"]

# The suite neither reads nor writes the user's on-disk light records
# (bench_sim.render.record_store), so every test renders what it counts; set at import, so the
# processes the tests start (commands, Dask workers) inherit it. Tests of the store turn it on
# with monkeypatch.
os.environ.setdefault("BENCH_SIM_RECORD_CACHE", "off")


@pytest.fixture(autouse=True)
def _a_test_process_stays_one() -> Iterator[None]:
    """No test makes the test process ``bench-sim``'s own. Importing the program module,
    ``bench_sim.__main__``, does so by design (its signal handlers become the process's; after a
    command, a signal ends the process at once with ``os._exit``): a test that imported it left
    its xdist worker so, and a later test's own signal ended the worker without a word (the worker
    that died in about half of the full runs). Commands are run as processes or through
    ``bench_sim.cli``."""
    yield
    interrupts = sys.modules.get("bench_sim.io.interrupts")
    assert "bench_sim.__main__" not in sys.modules and not getattr(interrupts, "_OWN_PROCESS", False), (
        "this test made the test process bench-sim's own (it imported bench_sim.__main__)")


@pytest.fixture
def disk_stores(monkeypatch: pytest.MonkeyPatch, tmp_path: Any) -> Any:
    """The disk stores (records, textures, kernels, a sweep's camera) turned on, at their default
    size bound, in a fresh cache folder; that folder."""
    monkeypatch.setenv("BENCH_SIM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv(record_store.ENV_SWITCH, "on")
    monkeypatch.delenv(record_store.ENV_SIZE, raising=False)
    return tmp_path / "cache"


def make_cfg(**sections: Any) -> BenchConfig:
    """The default rig with sections overridden, e.g. ``make_cfg(sensor={"rows": 8})``."""
    return with_overrides(load_config(), sections)


#: every noise source of the pixel model switched off
ALL_OFF = dict(
    shot_noise=False, dark_noise=False, read_noise=False, prnu_enabled=False,
    dsnu_enabled=False, column_fpn=False, quantization=False,
)

TINY = {
    "sensor": {"rows": 12, "columns": 48},
    "target": {"panel_lines": 96, "panel_columns": 48},
    "render": {"spp": 16, "subpixels": 4},
    "fusion": {"mu1": 2, "mu2": 8},
}


def tiny_cfg(**sections: Any) -> BenchConfig:
    """A 12 x 48 sensor on the default rig (spot edge and wedges in view), overridable."""
    return with_overrides(with_overrides(load_config(), TINY), sections)


@pytest.fixture
def tiny() -> BenchConfig:
    return tiny_cfg()


def subpixel_shift(a: np.ndarray, b: np.ndarray) -> float:
    """Lag [samples] at which ``b`` best matches ``a`` (``b(x) ~ a(x - lag)``): the peak of their
    cross-correlation, refined by a parabola through the three samples around it."""
    a = a - a.mean()
    b = b - b.mean()
    xc = np.correlate(b, a, mode="full")
    k = int(np.argmax(xc))
    y0, y1, y2 = xc[k - 1], xc[k], xc[k + 1]
    return k - (len(a) - 1) + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
