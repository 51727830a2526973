"""Execute notebooks/optimize_small.ipynb headless (its cells assert the volume and the descent).

Marked slow (about a minute: a kernel, the adjoint step's compilation, eight steps); the same
loop on a real case runs by default in `test_optimize.py::test_psi_decreases_on_a_tiny_real_case_through_the_cli`.
Missing notebook machinery is a failure, not a skip.
"""

import pytest
from notebook_runner import run_notebook


@pytest.mark.slow
def test_optimize_small_notebook_runs():
    run_notebook("optimize_small.ipynb", timeout=300)
