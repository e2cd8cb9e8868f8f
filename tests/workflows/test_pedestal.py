"""``fuse --pedestal`` defaults to the pedestal bench_sim's own stage images carry in their
metadata, and to 0 (stated) for a camera's plain files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bench_sim.cli import app
from bench_sim.io import read_exr, write_exr, write_png, write_tiff16
from bench_sim.runtime.provenance import provenance
from bench_sim.workflows.pedestal import default_pedestal_dn, file_pedestal_dn
from tests.conftest import tiny_cfg

runner = CliRunner()


def _words(pedestal: int) -> tuple[np.ndarray, np.ndarray]:
    s1 = np.arange(0, 4096 - pedestal, 7, dtype=np.int64)[None, :]
    s2 = np.minimum(8 * s1, 4095 - pedestal)
    return (s1 + pedestal).astype(np.uint16), (s2 + pedestal).astype(np.uint16)


@pytest.mark.parametrize("pedestal", [64, 200])
def test_bench_sim_tiffs_are_fused_with_their_own_pedestal(tmp_path: Path, pedestal: int) -> None:
    cfg = tiny_cfg(dtdi={"pedestal_dn": pedestal})
    meta = provenance(cfg, 0)
    low, high = _words(pedestal)
    write_tiff16(tmp_path / "g1.tiff", low, meta)
    write_tiff16(tmp_path / "g2.tiff", high, meta)
    assert file_pedestal_dn(tmp_path / "g1.tiff") == pedestal
    r = runner.invoke(app, ["fuse", str(tmp_path / "g1.tiff"), str(tmp_path / "g2.tiff"),
                            "--out", str(tmp_path / "hdr.exr")])
    assert r.exit_code == 0, r.stderr
    assert f"pedestal subtracted: {pedestal} DN (dtdi.pedestal_dn from both inputs'" in r.stdout
    chans, hdr_meta = read_exr(tmp_path / "hdr.exr")
    assert hdr_meta["pedestal_dn"] == pedestal
    # the noise-free response is linear through the origin: the pedestal is gone
    s1 = low.astype(np.float64) - pedestal
    below = (chans["source"][0] == 80) & (high[0] < 4095)  # unclipped stage-80 pixels
    assert np.allclose(chans["Y"][0][below], 8 * s1[0][below])


def test_plain_files_get_zero_and_it_is_said(tmp_path: Path) -> None:
    low, high = _words(0)
    write_png(tmp_path / "a.png", low)
    np.save(tmp_path / "b.npy", high)
    value, why = default_pedestal_dn(tmp_path / "a.png", tmp_path / "b.npy")
    assert value == 0 and "no bench_sim metadata" in why
    r = runner.invoke(app, ["fuse", str(tmp_path / "a.png"), str(tmp_path / "b.npy"),
                            "--out", str(tmp_path / "hdr.exr")])
    assert r.exit_code == 0, r.stderr
    assert "pedestal subtracted: 0 DN (the inputs carry no bench_sim metadata" in r.stdout


def test_an_explicit_pedestal_wins_and_disagreeing_files_are_refused(tmp_path: Path) -> None:
    low, high = _words(64)
    write_tiff16(tmp_path / "g1.tiff", low, provenance(tiny_cfg(), 0))
    write_exr(tmp_path / "g2.exr", {"Y": high.astype(np.float32)},
              provenance(tiny_cfg(dtdi={"pedestal_dn": 32}), 0))
    assert file_pedestal_dn(tmp_path / "g2.exr") == 32
    r = runner.invoke(app, ["fuse", str(tmp_path / "g1.tiff"), str(tmp_path / "g2.exr"),
                            "--out", str(tmp_path / "hdr.exr")])
    assert r.exit_code == 2 and "disagree" in r.stderr and not (tmp_path / "hdr.exr").exists()
    r = runner.invoke(app, ["fuse", str(tmp_path / "g1.tiff"), str(tmp_path / "g2.exr"), "--pedestal", "64",
                            "--out", str(tmp_path / "hdr.exr")])
    assert r.exit_code == 0 and "64 DN (--pedestal)" in r.stdout
