"""A compiled entry point that says when it compiles.

`equinox.filter_jit` compiles a program on the first call for each static structure and each set of
array shapes, and reuses it after; that first call takes from seconds to minutes (tracing the solver
and the adjoint, then XLA), and without a word the user cannot tell a compile from a hang.
[`Program`][] wraps such a function: before a call that will compile it logs
`compiling <what> (first call for these shapes and settings)...` on the package's logger
(`logging.getLogger("ffr_jax")`, level INFO), and after it the time the call took. Later calls with
the same structure and shapes log nothing.

Python's cyclic garbage collector is paused during that first call (`collector_paused`; the kept programs of
`_sensitivity/_cached.py` use it too). Tracing a solver and its adjoint allocates millions of small objects
(tracers, jaxpr equations, their parameters) that all live until the program is lowered; the collector starts a
collection every 700 net allocations and scans them again and again, none of them garbage. On the README
mechanism's gradient it took ~8 % of the first call's samples (`perf`), and its tracing 5.3-6.5 s with it on
against 4.5-5.3 s paused (`benchmarks/RESULTS.md`, "Compile time"). The process's setting is the user's and is
restored after (a collector the user turned off stays off; a nested pause changes nothing); what became garbage
meanwhile goes at the next collection.

The signature that decides "first call" is the one `filter_jit` caches on: the tree structure of the
arguments, their non-array leaves (hashable, as `filter_jit` requires) and the shapes and dtypes of
their array leaves.

The program is compiled with the package's XLA options (`_dynamics/_xla_flags.py`, `program_options`:
on CPU the concurrency-optimised scheduler and the new fusion emitters off), chosen at the first call, when
JAX's backend is known.
Called with traced arguments (inside a user's `jax.jit` or `jax.vmap`) it is traced into the caller's
program instead, without options of its own (JAX refuses compiler options on a nested jit).
"""

import contextlib
import gc
import logging
import time
from collections.abc import Callable

import equinox as eqx
import jax

from ._dynamics._xla_flags import program_options

logger = logging.getLogger("ffr_jax")


@contextlib.contextmanager
def collector_paused():
    """Pause Python's cyclic garbage collector inside the `with` block; restore its state after (module docstring)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _signature(args) -> tuple:
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    static_leaves, static_def = jax.tree_util.tree_flatten(static)
    return treedef, static_def, tuple(static_leaves), tuple((leaf.shape, str(leaf.dtype)) for leaf in leaves)


class Program:
    """`equinox.filter_jit(function)`, logging its compiles (module docstring).

    **Arguments:**
    - `function`: the function to compile.
    - `what`: how the log names it, e.g. `"the gradient"`; a call may add a detail
      (`program(*args, detail="discrete adjoint of Rodas5P")`).
    """

    def __init__(self, function: Callable, what: str):
        self._function = function
        self._jitted = None  # built at the first call: its XLA options depend on the backend
        # Called inside another program (a user's jax.jit, or jax.vmap): JAX takes compiler options only on a
        # top-level jit, and the outer program is compiled with its own, so the function is jitted without them.
        self._nested = eqx.filter_jit(function)
        self._what = what
        self._seen: set = set()
        self.__wrapped__ = function

    def __call__(self, *args, detail: str = ""):
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(args)):
            return self._nested(*args)  # traced into the caller's program: compiled, and logged, with it
        if self._jitted is None:
            self._jitted = eqx.filter_jit(self._function,
                                          compiler_options=program_options(jax.default_backend()) or None)
        try:
            key = _signature(args)
            hash(key)
        except TypeError:  # an unhashable static part: filter_jit will say so itself
            return self._jitted(*args)
        if key in self._seen:
            return self._jitted(*args)
        what = f"{self._what} ({detail})" if detail else self._what
        logger.info("compiling %s (first call for these shapes and settings)...", what)
        start = time.perf_counter()
        try:
            with collector_paused():  # tracing allocates millions of objects that live until lowered
                out = self._jitted(*args)
                if not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(out)):
                    jax.block_until_ready(out)
        finally:  # compiled, whether or not the run then raised (a failed check, a dead point)
            self._seen.add(key)
        logger.info("%s: compiled and ran in %.1f s", what, time.perf_counter() - start)
        return out
