"""Execute notebooks/optimize_small.ipynb headless (its cells assert the volume and the descent).

Marked slow (about a minute: a kernel, the adjoint step's compilation, eight steps); the same
loop on a real case runs by default in `test_optimize.py::test_psi_decreases_on_a_tiny_real_case_through_the_cli`.
Missing notebook machinery is a failure, not a skip.
"""

import json
import pathlib

import pytest
from notebook_runner import run_notebook

NOTEBOOK = pathlib.Path(__file__).parent.parent / "notebooks" / "optimize_small.ipynb"


@pytest.mark.slow
def test_optimize_small_notebook_runs():
    run_notebook("optimize_small.ipynb", timeout=300)


def test_optimize_small_notebook_is_stored_executed():
    # The notebook is kept with its outputs (a reader sees the results without running it): every code
    # cell ran, in order, without an error, and the figures are in it. Re-run it with
    # `nbclient` after changing it (the slow test above executes a copy without writing it).
    cells = [c for c in json.loads(NOTEBOOK.read_text())["cells"] if c["cell_type"] == "code"]
    assert [c["execution_count"] for c in cells] == list(range(1, len(cells) + 1)), "run top to bottom once"
    outputs = [o for c in cells for o in c["outputs"]]
    assert not [o for o in outputs if o["output_type"] == "error"]
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= 3, "the design, history and MMA figures"
