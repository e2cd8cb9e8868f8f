"""The resume journal (one record per finished task) and the progress bar helper."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from bench_sim.io import write_json
from bench_sim.runtime.journal import Journal, read_records, write_record
from bench_sim.runtime.progress import progress_bar


def test_a_record_has_the_bytes_of_write_json_and_no_temporaries_stay(tmp_path: Path) -> None:
    rec = {"point": 3, "b": np.float32(0.5), "a": [np.int64(2)], "path": Path("x")}
    write_json(tmp_path / "ref.json", rec)
    journal = Journal(tmp_path / "points", key="point", digits=6)
    path = journal.write(rec)
    assert path == tmp_path / "points" / "000003.json"
    assert path.read_bytes() == (tmp_path / "ref.json").read_bytes()
    assert [p.name for p in (tmp_path / "points").iterdir()] == ["000003.json"]
    assert journal.read() == {3: {"point": 3, "b": 0.5, "a": [2], "path": "x"}}


def test_unreadable_records_count_as_not_done_with_one_warning_each(tmp_path: Path) -> None:
    folder = tmp_path / "samples"
    write_record(folder / "00000000.json", {"sample": 0, "status": "complete"})
    (folder / "00000001.json").write_text("")  # empty: a torn write
    (folder / "00000002.json").write_text('{"sample": 2, "sta')  # cut short
    (folder / "00000003.json").write_text('{"other": 1}')  # no index
    (folder / ".00000004.json.partial-1-abc.json").write_text("{}")  # a temporary: not a record
    with pytest.warns(RuntimeWarning) as caught:
        records = read_records(folder, "sample")
    assert list(records) == [0]
    lines = [str(w.message) for w in caught]
    assert len(lines) == 3 and all("\n" not in m and "not done" in m for m in lines)
    assert {Path(m.split(": ")[1]).name for m in lines} == {"00000001.json", "00000002.json", "00000003.json"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # warned once per file: no second warning
        assert list(read_records(folder, "sample")) == [0]


def test_missing_journal_is_empty(tmp_path: Path) -> None:
    assert read_records(tmp_path / "none", "point") == {}


@pytest.mark.parametrize("enabled", [True, False])
def test_progress_bar_is_silent_off_a_terminal(enabled: bool, capsys: pytest.CaptureFixture[str]) -> None:
    with progress_bar("sweep", 3, "points", enabled=enabled, note="x") as bar:
        for _ in range(3):
            bar.advance()
        bar.note("1 failed")
    assert capsys.readouterr().out == ""
