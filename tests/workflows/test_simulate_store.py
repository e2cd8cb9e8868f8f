"""``simulate --format zarr`` streams its stages into the store while the pass runs (issue 26):
the store is byte for byte the in-memory dataset written at the end, and holds only the rows of
chunks in flight."""

from __future__ import annotations

import numpy as np
import pytest

import bench_sim
from bench_sim.config import load_config, with_overrides
from bench_sim.pipeline import one_pass, run_pass
from bench_sim.workflows import simulate_store
from bench_sim.workflows.simulate import run_simulate, write_simulation
from tests.conftest import TINY
from tests.workflows.test_simulate import _tiny_toml


def _files(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("stages", ["2,8", "all"])
def test_streamed_store_is_the_dataset_written_at_the_end(tmp_path, stages):
    """Same config and seed: the streamed store and ``to_zarr`` of :func:`bench_sim.simulate`'s
    dataset have the same files with the same bytes (values, chunks, attributes, metadata)."""
    cfg = _tiny_toml(tmp_path)
    run_simulate(cfg, stages=stages, seed=4, out=tmp_path / "streamed", progress=False)
    st = list(range(1, 13)) if stages == "all" else [2, 8]
    ds = bench_sim.simulate(cfg, stages=st, seed=4)
    (tmp_path / "whole").mkdir()
    write_simulation(ds, tmp_path / "whole", "zarr", {})
    streamed = _files(tmp_path / "streamed" / "simulation.zarr")
    whole = _files(tmp_path / "whole" / "simulation.zarr")
    assert streamed.keys() == whole.keys()
    assert [k for k in whole if streamed[k] != whole[k]] == []


def test_the_sink_holds_only_the_rows_in_flight(tmp_path, monkeypatch):
    """Over a pass of 20 rows of chunks (8 lines each), the store's sink holds no more rows than
    the lines in flight span: a band of the reflectance (16 lines), the ``max(stages)`` lines in
    progress and a chunk of frames (16); the lines written are the pass's."""
    import zarr

    small_chunks = lambda dims, shape: (*(1,) * (len(shape) - 2), 8, 48)  # noqa: E731
    monkeypatch.setattr(simulate_store, "store_chunks", small_chunks)
    monkeypatch.setattr(one_pass, "TRUTH_BAND_LINES", 16)
    cfg = with_overrides(load_config(), {**TINY, "lines": 160})
    most = {}

    class Watched(simulate_store.ZarrPassSink):
        def write(self, name, stage, line0, block):
            super().write(name, stage, line0, block)
            most[name] = max(most.get(name, 0), len(self.rows[name]))

    sinks = []

    def make(setup):
        sinks.append(Watched(tmp_path / "s.zarr", cfg, (1, 12), 0, setup, truth=True))
        return sinks[-1]

    run_pass(cfg, (1, 12), 0, sink=make)
    sinks[0].close()
    assert most and max(most.values()) <= (16 + 12 + 16) // 8 + 2
    ref = run_pass(cfg, (1, 12), 0).dataset
    assert np.array_equal(zarr.open_array(tmp_path / "s.zarr" / "dn")[...], ref.dn.values)
