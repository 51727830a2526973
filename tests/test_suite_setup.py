"""The suite's own machinery: pytest-xdist's groups reach its scheduler (tests/conftest.py).

Each module's compiled programs are built once only if all its tests run on one worker; with a pytest
that pytest-xdist cannot mark (pytest 9.2 with xdist 3.8) the groups are silently dropped and the suite
takes ~40 % longer. This fails instead.
"""

import os

import pytest


def test_xdist_groups_reach_the_scheduler(request):
    if not os.environ.get("PYTEST_XDIST_WORKER") or not request.config.getvalue("loadgroup"):
        pytest.skip("not run by pytest-xdist with --dist loadgroup")
    assert request.node.nodeid.endswith("@test_suite_setup"), (
        f"{request.node.nodeid}: pytest-xdist did not tag this test with its group; check the pytest and "
        "pytest-xdist versions against the pin in pyproject.toml")
