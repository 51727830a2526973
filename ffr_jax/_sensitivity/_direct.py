"""The direct (forward sensitivity) method: forward-mode differentiation through the solver."""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp

from ._autodiff import _psi
from ._base import AbstractSensitivity


class Direct(AbstractSensitivity):
    """Forward-mode sensitivities `d y / d p_k` integrated with the state (`diffrax.ForwardMode`),
    one tangent per scalar parameter of the scene, batched with `jax.vmap` over `chunk`-sized
    blocks. Its cost grows with the number of *parameters* (the body data: a few hundred), not
    with the number of design variables, which enter through one VJP of `p(x)`.
    """

    chunk: int | None = None

    def value_and_grad_scene(self, case, scene, *, rtol, atol, solver, max_steps):
        dyn, static = eqx.partition(scene, eqx.is_inexact_array)
        flat, unravel = jax.flatten_util.ravel_pytree(dyn)
        adjoint = diffrax.ForwardMode()

        def psi_flat(v):
            return _psi(case, eqx.combine(unravel(v), static), rtol, atol, solver, max_steps, adjoint)

        def tangent(e):
            return jax.jvp(psi_flat, (flat,), (e,))

        basis = jnp.eye(flat.size, dtype=flat.dtype)
        psi, grads = jax.lax.map(tangent, basis, batch_size=self.chunk or flat.size)
        return psi[0], unravel(grads)
