"""The example notebook (docs/python-example.ipynb) runs from top to bottom in a Jupyter kernel, and shows images."""

import pathlib

import nbformat
from nbclient import NotebookClient

NOTEBOOK = pathlib.Path(__file__).resolve().parents[3] / "docs" / "python-example.ipynb"


def test_the_example_notebook_runs_and_shows_images(tmp_path):
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    # The sponge's default view and the two rings side by side.
    assert len(images) >= 2, [o.output_type for o in outputs]
    text = "".join(o.get("text", "") for o in outputs)
    assert "view loaded after" in text and "levels" in text
