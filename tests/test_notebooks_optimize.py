"""Execute notebooks/optimize_small.ipynb headless (its cells assert the volume and the descent)."""

import pathlib

import pytest

NOTEBOOK = pathlib.Path(__file__).parent.parent / "notebooks" / "optimize_small.ipynb"


@pytest.mark.slow
def test_optimize_small_notebook_runs():
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    jupyter_client = pytest.importorskip("jupyter_client.kernelspec")
    try:
        jupyter_client.KernelSpecManager().get_kernel_spec("python3")
    except jupyter_client.NoSuchKernel:
        pytest.skip("no 'python3' Jupyter kernel is registered (pip install ipykernel)")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(notebook, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()


def test_optimize_small_notebook_is_stored_executed():
    # The notebook is kept with its outputs (a reader sees the results without running it): every code
    # cell ran, in order, without an error, and the figures are in it. Re-run it with
    # `nbclient` after changing it (the slow test above executes a copy without writing it).
    import json

    cells = [c for c in json.loads(NOTEBOOK.read_text())["cells"] if c["cell_type"] == "code"]
    assert [c["execution_count"] for c in cells] == list(range(1, len(cells) + 1)), "run top to bottom once"
    outputs = [o for c in cells for o in c["outputs"]]
    assert not [o for o in outputs if o["output_type"] == "error"]
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= 3, "the design, history and MMA figures"
