"""Execute the issue-6 notebooks headless at their small size (their cells assert what they show).

`FFR_NOTEBOOK_SIZE=small` is set for the kernel; `reference` runs the paper's case instead
(minutes for the work–precision sweep, hours for the finite differences of Figs. 5–6).
"""

import pathlib

import pytest

NOTEBOOKS = pathlib.Path(__file__).parent.parent / "notebooks"


@pytest.mark.parametrize("name", ["figs5_6_gradient.ipynb", "work_precision.ipynb"])
def test_notebook_runs_at_small_size(name, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    kernelspec = pytest.importorskip("jupyter_client.kernelspec")
    try:
        kernelspec.KernelSpecManager().get_kernel_spec("python3")
    except kernelspec.NoSuchKernel:
        pytest.skip("no 'python3' Jupyter kernel is registered (pip install ipykernel)")
    monkeypatch.setenv("FFR_NOTEBOOK_SIZE", "small")
    path = NOTEBOOKS / name
    notebook = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}}).execute()


@pytest.mark.slow  # an adjoint compile and six MMA steps in a fresh kernel (minutes); issue 14's worked example
def test_two_links_notebook_runs_at_small_size(monkeypatch):
    test_notebook_runs_at_small_size("two_links.ipynb", monkeypatch)
