"""The exploratory notebooks run top to bottom (nbclient, ``python3`` kernel, Agg backend).

Each notebook is executed on its default path (a dataset simulated into a temporary folder)
with the ``tiny`` preset injected into its first cell; a cell that raises fails the test.
The stored notebooks must carry no outputs.
"""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
MAX_STORED_BYTES = 60_000


def _first_code_cell(nb: nbformat.NotebookNode) -> nbformat.NotebookNode:
    return next(cell for cell in nb.cells if cell.cell_type == "code")


def test_the_notebooks_exist() -> None:
    names = [p.name for p in NOTEBOOKS]
    assert names == [
        "01_dataset_tour.ipynb",
        "02_clustering_study.ipynb",
        "03_tracking_and_errors.ipynb",
        "04_drone_types.ipynb",
    ]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_stored_clean(path: Path) -> None:
    assert path.stat().st_size < MAX_STORED_BYTES
    # as stored: nbformat.read gives a 4.5 cell without an id one and only warns (a hard error
    # in future nbformat versions)
    stored = json.loads(path.read_text(encoding="utf-8"))
    if (stored["nbformat"], stored["nbformat_minor"]) >= (4, 5):
        ids = [cell.get("id") for cell in stored["cells"]]
        assert None not in ids, f"{path.name}: a cell without an id"
        assert len(set(ids)) == len(ids), f"{path.name}: repeated cell ids"
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [], f"{path.name}: stored with outputs"
            assert cell.execution_count is None, f"{path.name}: stored with execution counts"
    first = _first_code_cell(nb).source
    assert "DATA = None" in first and "PRESET = " in first


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MPLBACKEND", "Agg")  # the kernel inherits it: no display needed
    nb = nbformat.read(path, as_version=4)
    _first_code_cell(nb).source += '\nPRESET = "tiny"  # injected by tests/test_notebooks.py\n'
    client = NotebookClient(
        nb,
        timeout=300,
        kernel_name="python3",
        resources={"metadata": {"path": str(NOTEBOOK_DIR)}},
    )
    client.execute()  # raises CellExecutionError when a cell raises
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    assert not errors
