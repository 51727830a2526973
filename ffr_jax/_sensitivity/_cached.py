"""A case's design gradient as programs that JAX's persistent compilation cache can keep.

JAX writes no persistent cache entry for a program with host callbacks, and a design gradient has
two kinds of them: the runtime checks of equinox (`eqx.error_if`: Newton's method failing, a dead
point, the step budget of a solve), which are `jax.pure_callback`s in equinox's default `raise`
mode, and the sparse modal solver (SciPy's Lanczos through `jax.pure_callback`). A command-line run
of `value_and_grad(case, x)` therefore compiles everything again in every process, cache or not
(measured: 90 s of compilation in the first and in the second `ffr-jax gradient slider-crank`).

Nor does the persistent cache skip tracing: turning the Python of diffrax, the model and the
adjoint into a program takes most of that time (measured on a 12 x 2 rod: 70 s with every XLA program
loaded from the cache, 70 s without, on a loaded machine). So the scene gradient below is also kept
as an exported program (`jax.export`: serialized StableHLO, keyed by the package's source, the JAX
versions, the static structure and the shapes) next to the XLA cache; a later process loads it
instead of tracing.

[`compile_value_and_grad`][] splits the computation at the scene, the way the gradient flows:

1. the design map with its VJP (`x -> scene`: FE model, modal reduction, body data; it may call
   SciPy, is compiled in every process, and is small);
2. the objective's gradient with respect to the scene (the forward and backward solves: nearly all
   of the compile time), traced with equinox's checks in `nan` mode, which has no callbacks, so the
   persistent cache keeps it, and it is exported (see above). A check that fails makes the result NaN; the same computation then
   runs again through [`ffr_jax.value_and_grad_scene`][] with the checks raising, so the user sees
   the package's own message, never a NaN;
3. the pull-back of the scene gradient to the design (the VJP of step 1).

The numbers are those of `value_and_grad(case, x, method)`: the design gradient of every method
but finite differences is the pull-back of its scene gradient (see `AbstractSensitivity`).
"""

import contextlib
import hashlib
import importlib.metadata
import os
import pathlib
import re
import time
import warnings
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from .._dynamics._case import Case
from .._sensitivity._base import AbstractSensitivity
from .._sensitivity._finite_differences import FiniteDifferences

try:  # where equinox reads its error mode when a check is traced (equinox 0.11 - 0.13)
    import equinox._errors as _eqx_errors

    _HAS_ERROR_MODE = hasattr(_eqx_errors, "EQX_ON_ERROR")
except ImportError:  # pragma: no cover - a future equinox: fall back to one program
    _eqx_errors, _HAS_ERROR_MODE = None, False


@contextlib.contextmanager
def _checks_as_nan():
    """Trace equinox's runtime checks in `nan` mode (no host callback) inside the block.

    JAX reuses the traces of jitted functions (e.g. the consistent initial state, traced when the
    problem was built): its caches are cleared on entry, so that no check traced in `raise` mode
    slips in, and on exit, so that no later trace reuses a check in `nan` mode (a silent NaN).
    """
    old = _eqx_errors.EQX_ON_ERROR
    jax.clear_caches()
    _eqx_errors.EQX_ON_ERROR = "nan"
    try:
        yield
    finally:
        _eqx_errors.EQX_ON_ERROR = old
        jax.clear_caches()


def _finite(tree) -> bool:
    leaves = [leaf for leaf in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(leaf)]
    return all(bool(jnp.all(jnp.isfinite(leaf))) for leaf in leaves)


def _source_digest() -> str:
    """A digest of the package's Python source and the versions of the libraries it traces."""
    h = hashlib.sha256()
    for path in sorted(pathlib.Path(__file__).parent.rglob("*.py")):
        h.update(str(path.relative_to(pathlib.Path(__file__).parent)).encode())
        h.update(path.read_bytes())
    for name in ("jax", "jaxlib", "diffrax", "equinox", "lineax", "optimistix"):
        try:
            h.update(f"{name}={importlib.metadata.version(name)}".encode())
        except importlib.metadata.PackageNotFoundError:
            pass
    h.update(repr(jax.config.jax_enable_x64).encode())
    return h.hexdigest()


def _program_key(static, treedef, leaves, options) -> str | None:
    """The key of an exported program, or `None` when its static part has no stable text (e.g. a
    user's function, whose repr holds a memory address): such a program is traced every time."""
    text = repr((static, options)) + str(treedef)
    # A named function (e.g. a case's Newton guess) by its name; a lambda or a closure has no name
    # that identifies it, nor has any other object shown by its address.
    text = re.sub(r"<function ([\w.]+) at 0x[0-9a-f]+>", r"<function \1>", text)
    if " at 0x" in text:
        return None
    h = hashlib.sha256(_source_digest().encode())
    h.update(text.encode())
    h.update(repr([(leaf.shape, str(leaf.dtype)) for leaf in leaves]).encode())
    return h.hexdigest()[:32]


def _exported(key, directory, function, leaves):
    """The exported program of `function(*leaves)` from `directory`, or traced, exported and saved."""
    path = None if key is None or directory is None else pathlib.Path(directory) / f"{key}.jaxexport"
    if path is not None and path.is_file():
        try:
            return jax.export.deserialize(bytearray(path.read_bytes())), True
        except Exception:  # a corrupt or foreign file: trace again and overwrite it
            pass
    exported = jax.export.export(jax.jit(function))(*leaves)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.partial")
        partial.write_bytes(exported.serialize())
        os.replace(partial, path)  # atomic: a killed run leaves no half-written program behind
    return exported, False


def compile_value_and_grad(case: Case, x, method: AbstractSensitivity, *, rtol: float = 1e-10,
                           atol: float = 1e-12, max_steps: int = 200_000,
                           export_dir: str | os.PathLike | None = None) -> tuple[Callable, dict]:
    """Compile `x -> (psi, grad)` of a case as cacheable programs (see the module's docstring).

    **Arguments:**

    - `case`: a case (problem + design map); `x`: a design of it (fixes the shapes compiled for).
    - `method`: a sensitivity method object; finite differences (which differentiate the design
      directly) and an equinox without a settable error mode fall back to one program.
    - `rtol`, `atol`, `max_steps`: as in [`ffr_jax.value_and_grad`][].
    - `export_dir`: where exported programs are kept (`None`: trace every time).

    **Returns:** `(fun, info)`: `fun(x)` gives `(psi, grad)` for designs of `x`'s shapes; `info`
    holds `compile_s` (tracing, compiling or loading) and `exported_loaded` (whether the scene
    gradient came from `export_dir` without tracing).
    """
    from .._api import value_and_grad, value_and_grad_scene

    options = dict(rtol=rtol, atol=atol, max_steps=max_steps)
    start = time.perf_counter()
    if isinstance(method, FiniteDifferences) or not _HAS_ERROR_MODE:
        compiled = jax.jit(lambda x: value_and_grad(case, x, method, **options)).lower(x).compile()
        return compiled, dict(compile_s=time.perf_counter() - start, exported_loaded=False)

    problem = case.problem
    design = eqx.filter_jit(lambda x: eqx.filter_vjp(case.scene, case.check(x)))
    scene, pullback = design(x)  # (the FE stage runs once here: part of the compile time)
    dynamic, static = eqx.partition((problem, scene, method), eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    wanted = [leaf for leaf in jax.tree_util.tree_leaves(scene) if eqx.is_inexact_array(leaf)]

    def scene_gradient(*leaves):
        problem, scene, method = eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static)
        psi, g_scene = method.value_and_grad_scene(problem, scene, rtol=rtol, atol=atol, solver=None,
                                                   max_steps=max_steps)
        # Flat outputs (a serializable structure): the derivatives of the scene's float arrays in
        # the scene's leaf order.
        return psi, tuple(jax.tree_util.tree_leaves(eqx.filter(g_scene, eqx.is_inexact_array)))

    key = _program_key(static, treedef, leaves, options)
    with _checks_as_nan():
        try:
            exported, loaded = _exported(key, export_dir, scene_gradient, leaves)
        except Exception as err:  # a program jax.export cannot serialize: compiled as usual
            warnings.warn(f"ffr_jax: the scene gradient could not be exported ({type(err).__name__}: {err}); "
                          "it is traced in every process.", stacklevel=2)
            exported, loaded = None, False
        if exported is None:
            gradient = jax.jit(scene_gradient).lower(*leaves).compile()
        else:
            shapes = [tuple(a.shape) for a in exported.out_avals[1:]]
            if shapes != [leaf.shape for leaf in wanted]:
                raise AssertionError(f"scene gradient leaves {shapes} differ from the scene's float arrays")
            # XLA: from the persistent cache when it has the program
            gradient = jax.jit(exported.call).lower(*leaves).compile()
    pull = eqx.filter_jit(lambda pullback, g: pullback(g)[0])
    g_like = eqx.filter(scene, eqx.is_inexact_array)
    info = dict(compile_s=time.perf_counter() - start, exported_loaded=loaded)

    def fun(x):
        scene, pullback = design(x)
        dynamic = eqx.filter((problem, scene, method), eqx.is_array)
        psi, g_leaves = gradient(*jax.tree_util.tree_leaves(dynamic))
        if not (_finite(psi) and _finite(g_leaves)):
            # A check failed inside the cacheable program: run it again with the checks raising.
            value_and_grad_scene(problem, scene, method, **options)
            raise FloatingPointError(
                "The objective or its gradient is not finite, and no check of the package fired: "
                "rerun with `ffr_jax.value_and_grad(case, x)` and report the case.")
        g_scene = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(g_like), list(g_leaves))
        return psi, pull(pullback, g_scene)

    return fun, info


def cache_events() -> dict:
    """Counters of JAX's persistent compilation cache in this process: hits and misses so far.

    Registered on first use (`jax.monitoring` event listener); the counts start then.
    """
    global _COUNTS
    if _COUNTS is None:
        _COUNTS = {"cache_hits": 0, "cache_misses": 0}
        names = {"/jax/compilation_cache/cache_hits": "cache_hits",
                 "/jax/compilation_cache/cache_misses": "cache_misses"}

        def listen(event, **kwargs):
            if event in names:
                _COUNTS[names[event]] += 1

        jax.monitoring.register_event_listener(listen)
    return dict(_COUNTS)


_COUNTS: dict | None = None
