"""Headless execution of the notebooks for the tests (their cells assert what they show).

The notebook machinery (nbformat, nbclient, a `python3` kernel from ipykernel) is part of the
`[test]` extra: when it is missing the notebook tests fail, naming what to install, rather than
pass without running anything.
"""

import os
import pathlib

import nbclient
import nbformat
from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel

NOTEBOOKS = pathlib.Path(__file__).parent.parent / "notebooks"
# The smallest member of each notebook's case family that still tells its story (the notebooks
# read it; "reference" runs the paper's case instead: minutes to hours).
SIZE = "small"


def run_notebook(name: str, timeout: int = 600) -> None:
    """Execute `notebooks/<name>` in a fresh `python3` kernel at `FFR_NOTEBOOK_SIZE=small`.

    The kernel inherits this process's environment: `PYTHONPATH` (so that it imports the same
    `ffr_jax` as the tests) and the compilation-cache settings of `tests/conftest.py`.
    """
    try:
        KernelSpecManager().get_kernel_spec("python3")
    except NoSuchKernel as err:
        raise RuntimeError("No 'python3' Jupyter kernel is registered: install the test extra "
                           "(pip install -e '.[test]', which brings ipykernel).") from err
    path = NOTEBOOKS / name
    notebook = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute(env=dict(os.environ, FFR_NOTEBOOK_SIZE=SIZE))
