"""A case's design gradient as programs that a second process loads instead of tracing and compiling.

`ffr_jax.value_and_grad(case, x)` (a concrete design) and `ffr-jax gradient` run it: the first call on
a machine traces, exports and compiles the gradient and keeps it in the user's cache directory
([`cache_directory`][]: `$FFR_JAX_CACHE_DIR`, else `ffr_jax` in `$XDG_CACHE_HOME` or `~/.cache`;
`FFR_JAX_NO_CACHE=1` turns it off); a later process with the same case structure, shapes and settings
loads the exported program and its XLA executable from there. Turning it on also turns on JAX's
persistent compilation cache in `<cache directory>/xla`, unless the user has set one.

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

The gradient is split at the scene, the way it flows, into three programs, each traced with equinox's
checks in `nan` mode (no callbacks: the persistent cache keeps them) and exported (see above):

1. the FE stage, `x -> scene` (FE model, modal reduction, body data);
2. the objective's gradient with respect to the scene (the forward and backward solves: nearly all
   of the compile time);
3. the pull-back of the scene gradient to the design (the VJP of step 1).

A check that fails makes a result NaN; that step then runs again with the checks raising, so the user
sees the package's own message, never a NaN. A program that cannot be exported (e.g. an FE stage that
calls SciPy's sparse eigensolver through a callback) is compiled in every process as before (a note
`<key>.unexportable` next to the programs spares later processes the attempt to export it). Tracing in
`nan` mode clears JAX's in-memory caches before and after (`_checks_as_nan`): once per machine, shapes
and settings, other compiled functions of the process compile again on their next call.

The numbers are those of `value_and_grad(case, x, method)`: the design gradient of every method
but finite differences is the pull-back of its scene gradient (see `AbstractSensitivity`).
"""

import contextlib
import dataclasses
import functools
import logging
import hashlib
import importlib.metadata
import inspect
import os
import pathlib
import re
import time
import types
import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._compiled import collector_paused
from .._dynamics._case import Case
from .._dynamics._xla_flags import program_options
from .._errors import clean_errors
from ._base import AbstractSensitivity, psi_of
from ._finite_differences import FiniteDifferences

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
    # On the host with NumPy: `jnp.isfinite` compiles a small program per leaf shape (two per shape, ~0.1-0.3 s
    # each), 20 of them on a first call of the reference gradient.
    leaves = [leaf for leaf in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(leaf)]
    return all(bool(np.all(np.isfinite(np.asarray(leaf)))) for leaf in leaves)


@functools.cache
def _source_digest() -> str:
    """A digest of the package's Python source and the versions of the libraries it traces."""
    h = hashlib.sha256()
    package = pathlib.Path(__file__).parents[1]
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    for name in ("jax", "jaxlib", "diffrax", "equinox", "lineax", "optimistix"):
        try:
            h.update(f"{name}={importlib.metadata.version(name)}".encode())
        except importlib.metadata.PackageNotFoundError:
            pass
    h.update(repr(jax.config.jax_enable_x64).encode())
    return h.hexdigest()


def _functions_in(obj, seen=None):
    """Every Python function reachable from `obj` through modules' fields, containers and partials."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, types.FunctionType):
        yield obj
    elif isinstance(obj, functools.partial):
        yield from _functions_in((obj.func, obj.args, obj.keywords), seen)
    elif isinstance(obj, (tuple, list)):
        for item in obj:
            yield from _functions_in(item, seen)
    elif isinstance(obj, dict):
        for item in obj.values():
            yield from _functions_in(item, seen)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for field in dataclasses.fields(obj):
            yield from _functions_in(getattr(obj, field.name, None), seen)


def _function_token(function) -> str | None:
    """A text that identifies a function across processes: its module, name and code (bytecode, constants,
    names); `None` for a closure or a lambda, whose behaviour its code does not fix. A wrapper that names
    what it wraps (`functools.wraps`, e.g. a runtime type checker's) counts as the wrapped function."""
    function = inspect.unwrap(function)
    if not isinstance(function, types.FunctionType):
        return None
    if function.__closure__ or function.__name__ == "<lambda>":
        return None
    text = _code_text(function.__code__) + repr(function.__defaults__)
    if " at 0x" in text:  # a default shown by its address: nothing in the text fixes it across processes
        return None
    digest = hashlib.sha256(text.encode())
    return f"<function {function.__module__}.{function.__qualname__} {digest.hexdigest()[:16]}>"


def _code_text(code: types.CodeType) -> str:
    """A code object as text that is the same in every process: its bytecode, names and constants, nested code
    objects (comprehensions, generator expressions, inner functions) by their own text, not their `repr` (which
    shows their address: a function holding a generator expression got a new key in every process, so its
    programs were traced and exported again each time), and sets of constants in sorted order (their `repr`
    follows string hashing, which differs between processes)."""
    return f"{code.co_code.hex()} {code.co_names} ({', '.join(_constant_text(c) for c in code.co_consts)})"


def _constant_text(constant) -> str:
    if isinstance(constant, types.CodeType):
        return f"code {constant.co_qualname} [{_code_text(constant)}]"
    if isinstance(constant, (frozenset, set)):
        return f"frozenset({{{', '.join(sorted(_constant_text(c) for c in constant))}}})"
    if isinstance(constant, tuple):
        return f"({', '.join(_constant_text(c) for c in constant)},)"
    return repr(constant)


def _program_key(static, treedef, leaves, options) -> str | None:
    """The key of an exported program, or `None` when its static part has no text that identifies it
    across processes (a closure or a lambda, any other object shown by its address): such a program is
    not kept. A named function counts by its module, name and code, so that two functions of one name
    with different bodies never share a program."""
    text = repr((static, options)) + str(treedef)
    for function in _functions_in((static, options)):
        token = _function_token(function)
        if token is None:
            return None
        text = text.replace(f"<function {function.__qualname__} at 0x{id(function):x}>", token)
    if " at 0x" in text:
        return None
    h = hashlib.sha256(_source_digest().encode())
    # The platform the program is lowered for: an exported program runs only there (one exported on a GPU
    # is refused on the CPU: "exported for platforms ('cuda',) but it is used on ('cpu',)").
    h.update(jax.default_backend().encode())
    h.update(text.encode())
    h.update(repr([(leaf.shape, str(leaf.dtype)) for leaf in leaves]).encode())
    return h.hexdigest()[:32]


def _options() -> dict[str, bool]:
    """XLA options of the kept programs on this platform (`_dynamics/_xla_flags.py`: on CPU the
    concurrency-optimised scheduler off, which slows their long chains of tiny operations down, and the older
    fusion emitters, which compile them in less time)."""
    return program_options(jax.default_backend())


CACHE_ENV = "FFR_JAX_CACHE_DIR"
NO_CACHE_ENV = "FFR_JAX_NO_CACHE"


def cache_directory() -> pathlib.Path | None:
    """Where compiled programs are kept between processes, or `None` when that is turned off.

    `$FFR_JAX_CACHE_DIR` if set, else `ffr_jax` in the user's cache directory (`$XDG_CACHE_HOME` or
    `~/.cache`); `FFR_JAX_NO_CACHE=1` (or the command's `--no-cache`) turns it off. Exported programs go
    to `programs/`, JAX's persistent compilation cache to `xla/` (unless the user has set its directory).
    """
    if os.environ.get(NO_CACHE_ENV, "").strip() not in ("", "0"):
        return None
    if os.environ.get(CACHE_ENV):
        return pathlib.Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "ffr_jax"


def use_persistent_cache(directory: pathlib.Path) -> bool:
    """Turn on JAX's persistent compilation cache in `directory / "xla"` unless the user has set a cache
    directory of their own (then theirs is used); whether a persistent cache is on."""
    if jax.config.jax_compilation_cache_dir:
        return True
    try:
        (directory / "xla").mkdir(parents=True, exist_ok=True)
    except OSError as err:
        warnings.warn(f"ffr_jax: compilation cache off ({directory}: {err.strerror}).", RuntimeWarning, stacklevel=3)
        return False
    jax.config.update("jax_compilation_cache_dir", str(directory / "xla"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return True


def cacheable(method: AbstractSensitivity) -> bool:
    """Whether the design gradient of `method` splits into cacheable programs (not finite differences,
    which differentiate the design directly, nor with an equinox whose error mode cannot be set)."""
    return _HAS_ERROR_MODE and not isinstance(method, FiniteDifferences)


def _scene_of(case, x):
    """The scene of design `x` (the FE stage: FE model, modal reduction, body data)."""
    return case.scene(case.check(x))


def _pullback_of(case, x, g_scene):
    """The derivative `g_scene` of the scene pulled back to the design (the FE stage's VJP)."""
    return eqx.filter_vjp(case.scene, case.check(x))[1](g_scene)[0]


def _scene_gradient_of(problem, scene, method, options):
    """`(psi, d psi / d scene)` of the problem with `scene` (the forward and backward solves)."""
    rtol, atol, solver, max_steps = options
    return method.value_and_grad_scene(problem, scene, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps)


def _psi_of_scene(problem, scene, options):
    """`psi` of the problem with `scene` (the forward solve alone)."""
    rtol, atol, solver, max_steps = options
    return psi_of(problem.with_scene(scene), rtol=rtol, atol=atol, solver=solver, max_steps=max_steps, adjoint=None)


@clean_errors
@eqx.filter_jit
def _raising(function, *args):
    """`function(*args)` with the checks raising (after a check failed in a cacheable program)."""
    return function(*args)


def _is_array(leaf) -> bool:
    """An array, or the shape of one (programs are keyed and exported from shapes)."""
    return eqx.is_array(leaf) or isinstance(leaf, jax.ShapeDtypeStruct)


def _inexact(leaf) -> bool:
    return _is_array(leaf) and jnp.issubdtype(leaf.dtype, jnp.inexact)


def _leaves(args) -> list:
    return jax.tree_util.tree_leaves(eqx.filter(args, _is_array))


class Uncacheable(Exception):
    """A program has no key that identifies it across processes (e.g. a user's lambda in the scene)."""


class _Program(eqx.Module):
    """One compiled program with flat inputs (the array leaves of its arguments) and flat outputs."""

    compiled: Callable = eqx.field(static=True)
    loaded: bool = eqx.field(static=True)


class _Gradient(eqx.Module):
    """The three programs of a design gradient, and the structures that turn their flat outputs back into
    a scene, a scene gradient and a design."""

    scene: _Program
    gradient: _Program
    pullback: _Program
    scene_static: Any = eqx.field(static=True)
    scene_treedef: Any = eqx.field(static=True)
    g_treedef: Any = eqx.field(static=True)
    x_treedef: Any = eqx.field(static=True)
    seconds: float = eqx.field(static=True)

    @property
    def loaded(self) -> bool:
        """Whether the solves' program (nearly all of the compile time) came from the cache."""
        return self.gradient.loaded

    def __call__(self, case, x, method, options):
        scene_leaves = self.scene.compiled(*_leaves((case, x)))
        scene = eqx.combine(jax.tree_util.tree_unflatten(self.scene_treedef, scene_leaves), self.scene_static)
        if not _finite(scene):  # a check of the FE stage failed (NaN in the cacheable program): raise it
            _raising(_scene_of, case, x)
        psi, *g_leaves = self.gradient.compiled(*_leaves((case.problem, scene, method, options)))
        if not (_finite(psi) and _finite(g_leaves)):
            # A check failed: the forward solve alone with the checks raising first (most failures are its own:
            # the step budget, a dead point, a NaN integrand; it compiles in a fraction of the gradient's time),
            # then the whole gradient.
            _raising(_psi_of_scene, case.problem, scene, options)
            _raising(_scene_gradient_of, case.problem, scene, method, options)
            raise FloatingPointError("The objective or its gradient is not finite, and no check of the package "
                                     "fired: rerun with FFR_JAX_NO_CACHE=1 and report the case.")
        g_scene = jax.tree_util.tree_unflatten(self.g_treedef, list(g_leaves))
        grad = jax.tree_util.tree_unflatten(self.x_treedef, list(self.pullback.compiled(*_leaves((case, x, g_scene)))))
        if not _finite(grad):
            _raising(_pullback_of, case, x, g_scene)
            raise FloatingPointError("The design gradient is not finite, and no check of the package fired: rerun "
                                     "with FFR_JAX_NO_CACHE=1 and report the case.")
        return psi, grad


# Compiled gradients of this process by program keys (like the cache of a jitted function).
_COMPILED: dict[tuple, _Gradient] = {}


def _flat(function, static, treedef):
    def flat(*leaves):
        out = function(*eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static))
        return tuple(jax.tree_util.tree_leaves(eqx.filter(out, eqx.is_array)))

    return flat


@collector_paused()  # tracing allocates millions of objects that live until lowered (`_compiled.py`)
def _gradient_programs(case, x, method, options, export_dir, need_key: bool = False,
                       memo: bool = True) -> tuple[_Gradient, bool]:
    """The three compiled programs of a design gradient (see the module docstring), and whether this call
    made them (else they were compiled earlier in this process; `memo=False` loads or traces them anyway).
    A program without a key (see `_program_key`) is traced and not kept: `Uncacheable` where `need_key`."""
    shapes = eqx.filter_eval_shape(_scene_of, case, x)  # the scene by its shapes: nothing compiled yet
    scene_dynamic, scene_static = eqx.partition(shapes, _is_array)
    g_shapes = eqx.filter(shapes, _inexact)
    x_shapes = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(jnp.shape(a), jnp.result_type(a)), x)
    specs = {"scene": (_scene_of, (case, x)),
             "gradient": (_scene_gradient_of, (case.problem, shapes, method, options)),
             "pullback": (_pullback_of, (case, x, g_shapes))}
    parts = {}
    for name, (function, args) in specs.items():
        dynamic, static = eqx.partition(args, _is_array)
        leaves, treedef = jax.tree_util.tree_flatten(dynamic)
        leaves = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype) for leaf in leaves]
        key = _program_key((function.__name__, static), treedef, leaves, {})
        if key is None and need_key:
            raise Uncacheable
        parts[name] = (_flat(function, static, treedef), leaves, key)
    keys = tuple(key for _, _, key in parts.values())
    if memo and None not in keys and keys in _COMPILED:
        return _COMPILED[keys], False
    paths = {name: _load_path(key, export_dir) for name, (_, _, key) in parts.items()}
    exported = {name: _load(paths[name]) for name in parts}
    loaded = {name: exported[name] is not None for name in parts}  # kept by an earlier process, not traced here
    # A program an earlier process could not export (e.g. the FE stage with SciPy's Lanczos solver, a host
    # callback) is compiled directly: its export is not tried again, one trace less in every later process.
    unexportable = {name for name in parts if _unexportable(paths[name])}
    logger = logging.getLogger("ffr_jax")
    where = None if paths["gradient"] is None else paths["gradient"].parent
    logger.info(
        "getting the design gradient (first call in this process for these shapes and settings): %s...",
        f"loading it from the cache ({where})" if exported["gradient"] is not None else
        "compiling it" + ("" if where is None else f" (kept in {where} for later processes)"))
    start = time.perf_counter()
    if any(exported[name] is None and name not in unexportable for name in parts):
        with _checks_as_nan():  # traced without host callbacks, so that XLA's persistent cache keeps them
            for name, (flat, leaves, _) in parts.items():
                if exported[name] is None and name not in unexportable:
                    exported[name] = _try_export(paths[name], flat, leaves, f"the {name} program")
    programs = {}
    for name, (flat, leaves, _) in parts.items():
        if exported[name] is None:
            programs[name] = _Program(jax.jit(flat).lower(*leaves).compile(_options()), False)
        else:  # XLA: from the persistent cache when it has the program
            programs[name] = _Program(jax.jit(exported[name].call).lower(*leaves).compile(_options()), loaded[name])
    gradient = _Gradient(programs["scene"], programs["gradient"], programs["pullback"], scene_static,
                         jax.tree_util.tree_structure(scene_dynamic), jax.tree_util.tree_structure(g_shapes),
                         jax.tree_util.tree_structure(x_shapes), time.perf_counter() - start)
    if None not in keys:
        _COMPILED[keys] = gradient
    return gradient, True


def _load_path(key, export_dir):
    """Where the exported program of `key` is kept, or `None`."""
    return None if key is None or export_dir is None else pathlib.Path(export_dir) / f"{key}.jaxexport"


def _unexportable_path(path):
    return None if path is None else path.with_suffix(".unexportable")


def _unexportable(path) -> bool:
    """Whether an earlier process found the program of `path` not exportable (see `_mark_unexportable`)."""
    marker = _unexportable_path(path)
    return marker is not None and marker.is_file()


def _mark_unexportable(path, err: Exception) -> None:
    """Note next to `path` that its program cannot be exported (the reason inside), so that later processes
    compile it directly; the note carries the program's key, so a changed package or setting tries again."""
    marker = _unexportable_path(path)
    if marker is None:
        return
    try:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(f"{type(err).__name__}: {err}\n")
    except OSError:  # a read-only cache: tried again next time
        pass


def _try_export(path, function, leaves, what: str):
    """The program exported (and kept at `path`), or `None` where it cannot be (e.g. a host callback such as SciPy
    in the FE stage): then noted for later processes (`_mark_unexportable`), and the caller compiles it with the
    checks raising."""
    try:
        return _export(path, function, leaves)
    except Exception as err:  # noqa: BLE001 - any refusal of jax.export: the program still runs, compiled here
        logging.getLogger("ffr_jax").info("%s cannot be exported (%s: %s); it is compiled in every process", what,
                                          type(err).__name__, err)
        _mark_unexportable(path, err)
        return None


def _load(path):
    """The exported program at `path`, or `None` (none there, or a corrupt or foreign file)."""
    if path is None or not path.is_file():
        return None
    try:
        return jax.export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # traced again and overwritten
        return None


def _export(path, function, leaves):
    exported = jax.export.export(jax.jit(function))(*leaves)
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_suffix(f".{os.getpid()}.partial")
            partial.write_bytes(exported.serialize())
            os.replace(partial, path)  # atomic: a killed run leaves no half-written program behind
        except OSError as err:  # a full or read-only cache: the program still runs, only not kept
            warnings.warn(f"ffr_jax: the compiled gradient could not be kept in {path.parent} ({err.strerror}).",
                          RuntimeWarning, stacklevel=4)
    return exported


class _Kept(eqx.Module):
    """One compiled program of any function whose outputs are finite arrays, and the structure that turns
    its flat outputs back into the function's output."""

    compiled: Callable = eqx.field(static=True)
    out_static: Any = eqx.field(static=True)
    out_treedef: Any = eqx.field(static=True)
    loaded: bool = eqx.field(static=True)
    seconds: float = eqx.field(static=True)

    def __call__(self, function, args):
        out = eqx.combine(jax.tree_util.tree_unflatten(self.out_treedef, list(self.compiled(*_leaves(args)))),
                          self.out_static)
        if not _finite(out):  # a check failed in the cacheable program: run it again with the checks raising
            _raising(function, *args)
            raise FloatingPointError("A result is not finite, and no check of the package fired: rerun with "
                                     "FFR_JAX_NO_CACHE=1 and report the case.")
        return out


# Kept programs of this process by program key (like the cache of a jitted function).
_KEPT: dict[str, _Kept] = {}


def _structure(out_like, exported):
    """`(out_dynamic, out_static)` of `out_like` (the expected output, by its shapes) where its array leaves
    match the exported program's outputs one for one, else `None`."""
    if out_like is None or exported is None:
        return None
    out_dynamic, out_static = eqx.partition(out_like, _is_array)
    leaves = jax.tree_util.tree_leaves(out_dynamic)
    avals = exported.out_avals
    if len(leaves) != len(avals) or any(tuple(a.shape) != tuple(b.shape) or a.dtype != b.dtype
                                        for a, b in zip(leaves, avals)):
        return None
    return out_dynamic, out_static


def kept_call(function, args: tuple, directory: pathlib.Path, what: str, out_like=None):
    """`function(*args)` (outputs: finite arrays) through a program kept in `directory / "programs"`: loaded
    when a process kept it there, else traced with the checks in `nan` mode, exported and kept; `None` where
    the arguments have no key that identifies them across processes (then use the plain compiled path).
    Says on the package's logger, once per process and program, whether it compiles or loads.

    `out_like`: the output's structure with the shapes of its arrays, where the caller knows it without
    tracing (checked against the exported or loaded program's outputs); else it is found by tracing
    `function` abstractly once more (also where the program cannot be exported)."""
    dynamic, static = eqx.partition(args, _is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    shapes = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype) for leaf in leaves]
    key = _program_key((function.__name__, static), treedef, shapes, {})
    if key is None:
        return None
    if key not in _KEPT:
        with collector_paused():  # tracing allocates millions of objects that live until lowered
            logger = logging.getLogger("ffr_jax")
            path = _load_path(key, directory / "programs")
            loading = path.is_file()
            logger.info("%s %s (first call in this process for these shapes and settings)...",
                        "loading" if loading else "compiling", what)
            start = time.perf_counter()
            flat = _flat(function, static, treedef)
            exported = _load(path)
            if exported is None and not _unexportable(path):
                with _checks_as_nan():
                    exported = _try_export(path, flat, shapes, what)
            # The output's structure from the caller, checked against the exported program's outputs: the export is
            # then the only trace (before, a first process traced the function abstractly once more for it).
            structure = _structure(out_like, exported)
            if structure is None:
                structure = eqx.partition(eqx.filter_eval_shape(function, *args), _is_array)
                if out_like is not None and (jax.tree_util.tree_structure(eqx.partition(out_like, _is_array)[0])
                                             != jax.tree_util.tree_structure(structure[0])):
                    # The caller's structure is not the output's: a later process could not rebuild the output
                    # from it, so nothing is kept (the plain compiled path runs).
                    logger.info("%s: the expected output structure differs from the traced one; not kept", what)
                    return None
            out_dynamic, out_static = structure
            if exported is None:
                compiled = jax.jit(flat).lower(*shapes).compile(_options())
            else:  # XLA: from the persistent cache when it has the program
                compiled = jax.jit(exported.call).lower(*shapes).compile(_options())
            _KEPT[key] = _Kept(compiled, out_static, jax.tree_util.tree_structure(out_dynamic), exported is not None
                               and loading, time.perf_counter() - start)
            out = _KEPT[key](function, args)
            logger.info("%s: %s and ran in %.1f s (cache: %s)", what, "loaded" if _KEPT[key].loaded else "compiled",
                        time.perf_counter() - start, directory)
            return out
    return _KEPT[key](function, args)


def cached_value_and_grad(case: Case, x, method: AbstractSensitivity, *, rtol: float, atol: float, solver=None,
                          max_steps: int, export_dir=None) -> tuple[tuple, _Gradient, bool]:
    """`((psi, grad), programs, fresh)` of a case at a concrete design `x` through the cacheable programs:
    the FE stage, the scene gradient (the solves) and the FE stage's VJP, each loaded from `export_dir`
    when a process kept it there, else traced with the checks in `nan` mode and exported there (a failed
    check, a NaN, is rerun with the checks raising). `programs.loaded`: whether the solves' program came
    from the cache; `programs.seconds`: what getting the programs took; `fresh`: whether this call got them
    (else they were compiled earlier in this process). Raises `Uncacheable` where a program has no key
    (then use the plain compiled path).
    """
    options = (rtol, atol, solver, max_steps)
    programs, fresh = _gradient_programs(case, x, method, options, export_dir, need_key=True)
    return programs(case, x, method, options), programs, fresh


def compile_value_and_grad(case: Case, x, method: AbstractSensitivity, *, rtol: float = 1e-10,
                           atol: float = 1e-12, max_steps: int = 200_000, solver=None,
                           export_dir: str | os.PathLike | None = None) -> tuple[Callable, dict]:
    """Compile `x -> (psi, grad)` of a case as cacheable programs (what `ffr-jax gradient` runs).

    **Returns:** `(fun, info)`: `fun(x)` gives `(psi, grad)` for designs of `x`'s shapes; `info` holds
    `compile_s` (tracing, compiling or loading) and `exported_loaded` (whether the solves' program came
    from `export_dir` without tracing). Finite differences are compiled as one program (they
    differentiate the design directly).
    """
    start = time.perf_counter()
    if not cacheable(method):
        fd = jax.jit(lambda x: method.value_and_grad_design(case, case.check(x), rtol=rtol, atol=atol, solver=solver,
                                                            max_steps=max_steps))
        compiled = clean_errors(fd.lower(x).compile(_options()))
        return compiled, dict(compile_s=time.perf_counter() - start, exported_loaded=False)
    options = (rtol, atol, solver, max_steps)
    programs, _ = _gradient_programs(case, x, method, options, export_dir, memo=False)
    info = dict(compile_s=time.perf_counter() - start, exported_loaded=programs.loaded)

    def fun(x):
        return programs(case, x, method, options)

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
