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
