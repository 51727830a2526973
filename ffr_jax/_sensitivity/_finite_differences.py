"""Central finite differences in the design variables."""

import jax
import jax.numpy as jnp

from .._simulate import simulate
from ._base import AbstractSensitivity


class FiniteDifferences(AbstractSensitivity):
    """Central differences `(psi(x + h e_k) - psi(x - h e_k)) / (2 h)` on the design variables.

    **Fields:**
    - `step`: the perturbation `h` (the paper used 0.1; a converged one is ~1e-4…1e-6, with the
      forward tolerance far below `h^2`). `x +- h` must stay inside `[x_min, 1]`.
    - `entries`: optional indices of the design variables to difference (default: all); other
      entries of the returned gradient are NaN so that they cannot be mistaken for values.
    - `batch_size`: how many perturbed designs are simulated at once (`jax.lax.map` over
      `jax.vmap` batches).
    """

    step: float = 1e-5
    entries: tuple[int, ...] | None = None
    batch_size: int = 8

    def value_and_grad_scene(self, case, scene, *, rtol, atol, solver, max_steps):
        raise NotImplementedError("Finite differences act on the design, not on the scene parameters.")

    def value_and_grad_design(self, case, x, *, rtol, atol, solver, max_steps):
        def psi(xx):
            return simulate(
                case.model, case.scene(xx), case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
                solver=solver, rtol=rtol, atol=atol, max_steps=max_steps, jump_ts=case.jump_ts,
            ).psi

        idx = jnp.arange(x.size) if self.entries is None else jnp.asarray(self.entries, int)

        def central(k):
            e = jnp.zeros_like(x).at[k].set(self.step)
            return (psi(x + e) - psi(x - e)) / (2 * self.step)

        diffs = jax.lax.map(central, idx, batch_size=self.batch_size)
        grad = jnp.full_like(x, jnp.nan).at[idx].set(diffs)
        return psi(x), grad
