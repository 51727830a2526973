"""The direct (forward sensitivity) method: forward-mode differentiation through the solver."""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp

from ._base import AbstractSensitivity, parameters, problem_gradient, psi_of, with_parameters


class Direct(AbstractSensitivity):
    """Forward-mode sensitivities `d y / d p_k` integrated with the state (`diffrax.ForwardMode`),
    one tangent per scalar parameter of the problem, batched with `jax.vmap` over `chunk`-sized
    blocks. Its cost grows with the number of *parameters* (the body data: a few hundred), not
    with the number of design variables, which enter through one VJP of `p(x)`.
    """

    chunk: int | None = None

    def value_and_grad_problem(self, problem, *, rtol, atol, solver, max_steps):
        dyn, static = eqx.partition(parameters(problem), eqx.is_inexact_array)
        flat, unravel = jax.flatten_util.ravel_pytree(dyn)
        adjoint = diffrax.ForwardMode()

        def psi_flat(v):
            params = eqx.combine(unravel(v), static)
            return psi_of(with_parameters(problem, params), rtol=rtol, atol=atol, solver=solver,
                          max_steps=max_steps, adjoint=adjoint)

        def tangent(e):
            return jax.jvp(psi_flat, (flat,), (e,))

        basis = jnp.eye(flat.size, dtype=flat.dtype)
        psi, grads = jax.lax.map(tangent, basis, batch_size=self.chunk or flat.size)
        return psi[0], problem_gradient(problem, unravel(grads))
