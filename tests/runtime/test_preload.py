"""Libraries imported while a run's tasks are on a cluster (bench_sim.runtime.preload)."""

from __future__ import annotations

import sys

import pytest

from bench_sim.runtime.preload import FIGURES, import_modules


@pytest.mark.parametrize("name", ["colorsys", "json.tool"])
def test_a_module_is_imported(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, name, raising=False)
    import_modules([name])
    assert name in sys.modules


def test_a_module_that_fails_is_left_and_the_next_one_still_imported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    import_modules(["bench_sim_no_such_module", "colorsys"])
    assert "bench_sim_no_such_module" not in sys.modules
    assert "colorsys" in sys.modules


def test_the_figure_modules_draw_without_a_gui() -> None:
    """What is preloaded for figures is matplotlib's Agg canvas, never a GUI backend."""
    import_modules(FIGURES)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    canvas = FigureCanvasAgg(Figure(figsize=(1, 1)))
    canvas.draw()
    assert canvas.buffer_rgba().shape[2] == 4


def test_the_modules_are_imported_in_the_callers_thread(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Never on a thread of their own (CPython 3.11's ``ast.parse`` races another thread's: see
    the module docstring): the module body runs in this thread, and is done on return."""
    import threading

    (tmp_path / "bench_sim_probe_module.py").write_text(
        "import threading\nTHREAD = threading.current_thread().name\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "bench_sim_probe_module", raising=False)
    before = threading.active_count()
    import_modules(["bench_sim_probe_module"])
    assert sys.modules["bench_sim_probe_module"].THREAD == threading.current_thread().name
    assert threading.active_count() == before


@pytest.mark.parametrize("enabled", [True, False])
def test_the_modules_are_imported_with_the_collector_paused(tmp_path, monkeypatch, enabled: bool) -> None:
    """The garbage collector is off while they import (bench_sim.runtime.collector) and as it
    was afterwards; outside a bench-sim process nothing is frozen."""
    import gc

    (tmp_path / "bench_sim_gc_probe.py").write_text("import gc\nENABLED = gc.isenabled()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "bench_sim_gc_probe", raising=False)
    was, frozen = gc.isenabled(), gc.get_freeze_count()
    (gc.enable if enabled else gc.disable)()
    try:
        import_modules(["bench_sim_gc_probe"])
        assert sys.modules["bench_sim_gc_probe"].ENABLED is False
        assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()
    assert gc.get_freeze_count() == frozen
