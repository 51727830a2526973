"""The stored notebooks are valid nbformat 4.5 documents: every cell has its id, so reading them prints no
MissingIDFieldWarning (nbformat fills missing ids in silently today and will refuse them later)."""

import json
import pathlib
import warnings

import pytest

nbformat = pytest.importorskip("nbformat")

NOTEBOOKS = sorted((pathlib.Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_every_cell_has_an_id(path):
    raw = json.loads(path.read_text())
    missing = [k for k, cell in enumerate(raw["cells"]) if "id" not in cell]
    assert not missing, f"cells {missing} of {path.name} have no id: fix with nbformat.validator.normalize"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nbformat.validate(nbformat.read(path, as_version=4))
