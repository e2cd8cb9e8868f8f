"""Libraries imported beforehand on a low-priority thread (bench_sim.runtime.preload)."""

from __future__ import annotations

import sys

import pytest

from bench_sim.runtime.preload import FIGURES, import_in_background


@pytest.mark.parametrize("name", ["colorsys", "json.tool"])
def test_a_module_is_imported_once_the_thread_ends(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, name, raising=False)
    import_in_background([name]).join(timeout=60)
    assert name in sys.modules


def test_a_module_that_fails_is_left_and_the_next_one_still_imported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "colorsys", raising=False)
    thread = import_in_background(["bench_sim_no_such_module", "colorsys"])
    thread.join(timeout=60)
    assert not thread.is_alive()
    assert "bench_sim_no_such_module" not in sys.modules
    assert "colorsys" in sys.modules


def test_the_figure_modules_draw_without_a_gui() -> None:
    """What is preloaded for figures is matplotlib's Agg canvas, never a GUI backend."""
    import_in_background(FIGURES).join(timeout=120)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    canvas = FigureCanvasAgg(Figure(figsize=(1, 1)))
    canvas.draw()
    assert canvas.buffer_rgba().shape[2] == 4
