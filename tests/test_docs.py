"""The documentation keeps up with the package (cheap: no JAX program is compiled).

- Every public name has an API entry: a `::: ffr_jax.<name>` line in some page of `docs/`, so a new public name
  without documentation fails here (and `mkdocs build --strict`, run by `.ci/run`, then checks that its
  docstring renders and that its references resolve).
- No API entry names something that is not public (a removed or renamed name leaves no stale page).
- The README keeps the test command that `.ci/run` and the fresh-clone check (`shared/tools/fresh-test`) run.
"""

import re
from pathlib import Path

import ffr_jax

ROOT = Path(__file__).resolve().parent.parent
ENTRY = re.compile(r"^:::\s+ffr_jax\.([A-Za-z_][A-Za-z0-9_]*)\s*$", re.MULTILINE)


def _public_names() -> set[str]:
    """`ffr_jax.__all__`, or, in a package without one, every attribute not starting with an underscore."""
    names = getattr(ffr_jax, "__all__", None)
    if names is None:
        names = [n for n in dir(ffr_jax) if not n.startswith("_")]
    return set(names)


def _documented_names() -> dict[str, list[str]]:
    """Each name of a `::: ffr_jax.<name>` line in docs/, with the pages that hold it."""
    found: dict[str, list[str]] = {}
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for name in ENTRY.findall(page.read_text(encoding="utf-8")):
            found.setdefault(name, []).append(str(page.relative_to(ROOT)))
    return found


def test_every_public_name_has_an_api_entry():
    missing = sorted(_public_names() - set(_documented_names()))
    assert not missing, (
        f"{len(missing)} public name(s) of ffr_jax have no `::: ffr_jax.<name>` entry in docs/: {missing}. "
        "Add each to the API page of its topic (docs/api/*.md), preceded by its anchor line `[](){#<name>}`.")


def test_every_api_entry_is_a_public_name():
    documented = _documented_names()
    stale = {name: pages for name, pages in documented.items() if name not in _public_names()}
    assert not stale, f"API entries in docs/ name things that are not public names of ffr_jax: {stale}"
    twice = {name: pages for name, pages in documented.items() if len(pages) > 1}
    assert not twice, f"Public names documented on more than one page (keep one entry each): {twice}"


def test_readme_keeps_the_test_command_that_ci_runs():
    # shared/tools/fresh-test runs the first `pip install ... && python -m pytest ...` of the README.
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    commands = re.findall(r"pip install[^`]*&& *python -m pytest[^`]*", readme)
    assert commands and commands[0].strip() == 'pip install -e ".[test]" && python -m pytest -q', commands
