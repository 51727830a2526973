"""A compiled entry point that says when it compiles.

`equinox.filter_jit` compiles a program on the first call for each static structure and each set of
array shapes, and reuses it after; that first call takes from seconds to minutes (tracing the solver
and the adjoint, then XLA), and without a word the user cannot tell a compile from a hang.
[`Program`][] wraps such a function: before a call that will compile it logs
`compiling <what> (first call for these shapes and settings)...` on the package's logger
(`logging.getLogger("ffr_jax")`, level INFO), and after it the time the call took. Later calls with
the same structure and shapes log nothing.

The signature that decides "first call" is the one `filter_jit` caches on: the tree structure of the
arguments, their non-array leaves (hashable, as `filter_jit` requires) and the shapes and dtypes of
their array leaves.
"""

import logging
import time
from collections.abc import Callable

import equinox as eqx
import jax

logger = logging.getLogger("ffr_jax")


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
        self._jitted = eqx.filter_jit(function)
        self._what = what
        self._seen: set = set()
        self.__wrapped__ = function

    def __call__(self, *args, detail: str = ""):
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
            out = self._jitted(*args)
            if not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(out)):
                jax.block_until_ready(out)
        finally:  # compiled, whether or not the run then raised (a failed check, a dead point)
            self._seen.add(key)
        logger.info("%s: compiled and ran in %.1f s", what, time.perf_counter() - start)
        return out
