"""Every study notebook runs from top to bottom in quick mode (CASADI_KEYFRAME_QUICK=1)."""
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="the notebooks need the test extra: "
                               "pip install -e '.[test]'")
NotebookClient = pytest.importorskip("nbclient").NotebookClient

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


def test_the_studies_have_notebooks():
    names = {p.stem for p in NOTEBOOKS}
    assert {"integrator_accuracy", "gradient_accuracy", "optimizer_convergence"} <= names


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_in_quick_mode(path, monkeypatch):
    monkeypatch.setenv("CASADI_KEYFRAME_QUICK", "1")
    nb = nbformat.read(path, as_version=4)
    assert nb.cells[0].cell_type == "markdown" and "Question" in nb.cells[0].source
    assert "What we found" in nb.cells[-1].source
    assert any(o.get("output_type") == "display_data" for c in nb.cells if c.cell_type == "code"
               for o in c.outputs), "commit the notebook with the outputs of a full run"
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
