"""Execute notebooks/link_four_bar.ipynb headless at its small size (its cells assert the gradient
agreement, the area fraction and the descent).

Slow: the four-bar's gradient compiles twice (adjoint, autodiff; at the small size the optimisation loop runs the
adjoint program of the gradient check: 203 s in CI's slow set when it compiled its own), minutes on a 2-core CPU;
tests/test_link_four_bar.py checks the same gradient (slow set too).
"""

import pathlib

import pytest

NOTEBOOK = pathlib.Path(__file__).parent.parent / "notebooks" / "link_four_bar.ipynb"


@pytest.mark.slow
def test_link_four_bar_notebook_runs_at_small_size(monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    kernelspec = pytest.importorskip("jupyter_client.kernelspec")
    pytest.importorskip("gmsh")
    try:
        kernelspec.KernelSpecManager().get_kernel_spec("python3")
    except kernelspec.NoSuchKernel:
        pytest.skip("no 'python3' Jupyter kernel is registered (pip install ipykernel)")
    monkeypatch.setenv("FFR_NOTEBOOK_SIZE", "small")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(notebook, timeout=1800, kernel_name="python3",
                            resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()
