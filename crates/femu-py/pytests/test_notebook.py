"""The example notebook (``notebooks/femu_tour.ipynb``) runs from top to bottom: the demo,
the sensitivity maps drawn with matplotlib, an identification from a field given as arrays.
Skipped with a message where nbclient or matplotlib is not installed."""

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "femu_tour.ipynb"


def test_the_example_notebook_runs(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("matplotlib")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    # The committed notebook carries no outputs (they are made here).
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")
    client = nbclient.NotebookClient(
        nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    # The sensitivity figure was drawn.
    assert any("image/png" in o.get("data", {}) for o in outputs)
