"""The tutorials of ``docs/tutorials/`` run: each is a Jupyter notebook kept as a jupytext
percent-format ``.py`` file, executed cell by cell by nbclient in a Python kernel (ipykernel),
all of them one after another in one temporary folder (as a reader runs them), at the quick
sizes written in them. A cell that raises (their own asserts included) fails the test with the
tutorial's name and the cell's error. ``make docs-test`` runs these and the docs checks alone."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")

TUTORIALS = sorted((Path(__file__).resolve().parents[1] / "docs" / "tutorials").glob("[0-9]*.py"))


def test_there_are_the_six_tutorials() -> None:
    assert [p.stem[:2] for p in TUTORIALS] == ["01", "02", "03", "04", "05", "06"]


@pytest.mark.slow
def test_tutorials_execute_one_after_another_in_one_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the kernel runs this interpreter (the project's environment), in the one temporary folder
    monkeypatch.setenv("PATH", str(Path(sys.executable).parent) + os.pathsep + os.environ.get("PATH", ""))
    for path in TUTORIALS:
        nb = jupytext.read(path)
        client = nbclient.NotebookClient(
            nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}},
        )
        try:
            client.execute()
        except nbclient.exceptions.CellExecutionError as exc:
            pytest.fail(f"{path.name}: {str(exc)[-3000:]}")
        outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
        assert not [o for o in outputs if o.get("output_type") == "error"], path.name
