"""`ffr_jax._compiled.Program`, the package's compiled entry points, inside a user's own `jax.jit` and `jax.vmap`.

A program compiled with the package's XLA options (`program_options`) must still be callable from inside another
program: JAX refuses compiler options on a nested `jit` ("can only be passed to top-level jax.jit"), which made
`jax.jit(lambda x: fj.value_and_grad(case, x))` fail (found 26 Nov, bisecting the default route's time).
"""

import logging

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax._compiled
from ffr_jax._compiled import Program
from ffr_jax._dynamics._xla_flags import SCHEDULER_OPTION


def _cube(x, y):
    return jnp.sum(x**3) + y, 3.0 * x**2


def test_a_program_runs_inside_jit_and_vmap(caplog, monkeypatch):
    # The suite's XLA_FLAGS set the scheduler option, so program_options gives none here; a user's process
    # without XLA_FLAGS gets this one, and with it a nested jit failed.
    monkeypatch.setattr(ffr_jax._compiled, "program_options", lambda platform: {SCHEDULER_OPTION: False})
    program = Program(_cube, "the cube")
    x = jnp.arange(1.0, 4.0)
    with caplog.at_level(logging.INFO, logger="ffr_jax"):
        direct = program(x, 1.0)
        inside_jit = jax.jit(lambda x: program(x, 1.0))(x)
        batched = jax.vmap(lambda x: program(x, 1.0))(jnp.stack([x, 2.0 * x]))
    # Exact: the same few float64 operations on integers, whichever program runs them.
    np.testing.assert_array_equal(inside_jit[0], direct[0])
    np.testing.assert_array_equal(inside_jit[1], direct[1])
    np.testing.assert_array_equal(batched[0], [36.0 + 1.0, 8.0 * 36.0 + 1.0])
    np.testing.assert_array_equal(batched[1][1], 3.0 * (2.0 * x) ** 2)
    # Only the top-level call compiles a program of its own, and says so once.
    compiling = [r.getMessage() for r in caplog.records if r.getMessage().startswith("compiling the cube")]
    assert len(compiling) == 1, compiling
