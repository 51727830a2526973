"""The package's import structure (issue 29), read from the source with `ast` (nothing is imported):

- the top level holds at most the door (`_api`), its checks, errors, the compiled-program wrapper, the
  type aliases and `__main__`; the rest lives in subpackages, one room each;
- no module imports the package's top level (`import ffr_jax`): every import names the module it needs;
- the library never imports the application around it (`ffr_jax._app`: CLI, plots, export, the run
  driver); only the package's `__init__` (the public names) and `__main__` do;
- no import cycles between modules, counting the imports inside functions too (a lazy import is how a
  cycle hides).
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "ffr_jax"
TOP_LEVEL = {"__init__", "__main__", "_api", "_checks", "_compiled", "_errors", "_typing"}


def _modules() -> dict[str, tuple[Path, bool]]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        modules[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return modules


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """The package modules that module `name` imports (anywhere in its source)."""
    path, is_package = MODULES[name]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            targets = [f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in MODULES else prefix for a in node.names]
        else:
            continue
        for target in targets:
            if target != "ffr_jax" and not target.startswith("ffr_jax."):
                continue
            while target not in MODULES:
                target = target.rsplit(".", 1)[0]
            found.add(target)
    found.discard(name)
    return found


GRAPH = {name: _imports(name) for name in MODULES}


def test_the_top_level_holds_only_the_door():
    top = {p.stem for p in PACKAGE.glob("*.py")}
    assert top <= TOP_LEVEL, f"new top-level files {sorted(top - TOP_LEVEL)}: put them in the subpackage of their room"


def test_no_module_imports_the_package_top_level():
    offenders = sorted(m for m, deps in GRAPH.items() if m not in ("ffr_jax", "ffr_jax.__main__") and "ffr_jax" in deps)
    assert not offenders, f"{offenders} import ffr_jax itself: import the module you need relatively instead"


def test_the_library_does_not_import_the_application():
    app = "ffr_jax._app"
    offenders = sorted((m, sorted(d for d in deps if d == app or d.startswith(app + ".")))
                       for m, deps in GRAPH.items()
                       if not (m == app or m.startswith(app + ".")) and m not in ("ffr_jax", "ffr_jax.__main__")
                       and any(d == app or d.startswith(app + ".") for d in deps))
    assert not offenders, f"library modules import the application: {offenders}"


def _cycles() -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan); an import of an enclosing
    package (its `__init__` runs first anyway) is not an edge."""
    edges = {m: [d for d in deps if not m.startswith(d + ".")] for m, deps in GRAPH.items()}
    index, low, stack, on_stack, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in edges:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycles():
    assert not _cycles(), f"import cycles: {_cycles()}"


def test_the_checks_can_fail():
    # The graph is read right: the door imports the dynamics, the CLI imports the door, and a made-up
    # cycle is found.
    assert "ffr_jax._dynamics._problem" in GRAPH["ffr_jax._api"]
    assert "ffr_jax._api" in GRAPH["ffr_jax._app._cli"]
    GRAPH["ffr_jax._dynamics._problem"].add("ffr_jax._api")
    try:
        assert any("ffr_jax._api" in c and "ffr_jax._dynamics._problem" in c for c in _cycles())
    finally:
        GRAPH["ffr_jax._dynamics._problem"].discard("ffr_jax._api")
