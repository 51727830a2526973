"""Central finite differences in the design variables."""

import diffrax
import jax
import jax.flatten_util
import jax.numpy as jnp

from ._base import AbstractSensitivity, psi_of


class FiniteDifferences(AbstractSensitivity):
    """Central differences `(psi(x + h e_k) - psi(x - h e_k)) / (2 h)` on the design variables.

    **Fields:**
    - `step`: the perturbation `h` (the paper used 0.1; a converged one is ~1e-4…1e-6, with the
      forward tolerance far below `h^2`). `x +- h` must stay inside `[x_min, 1]`.
    - `entries`: optional indices of the design variables to difference (default: all); other
      entries of the returned gradient are NaN so that they cannot be mistaken for values. For a
      dict design the indices count in the flattened design (`jax.flatten_util.ravel_pytree`:
      bodies in sorted name order).
    - `batch_size`: how many perturbed designs are simulated at once (`jax.lax.map` over
      `jax.vmap` batches).
    """

    step: float = 1e-5
    entries: tuple[int, ...] | None = None
    batch_size: int = 8

    def value_and_grad_problem(self, problem, *, rtol, atol, solver, max_steps):
        raise ValueError("Finite differences act on the design, not on the problem's parameters: use "
                         "value_and_grad(case, x, 'fd'), or another method (e.g. 'adjoint') for problem gradients.")

    def value_and_grad_design(self, case, x, *, rtol, atol, solver, max_steps):
        adjoint = diffrax.RecursiveCheckpointAdjoint()
        x, unravel = jax.flatten_util.ravel_pytree(x)

        def psi(xx):
            return psi_of(case.problem.with_scene(case.scene(unravel(xx))), rtol=rtol, atol=atol, solver=solver,
                          max_steps=max_steps, adjoint=adjoint)

        idx = jnp.arange(x.size) if self.entries is None else jnp.asarray(self.entries, int)
        n = idx.size
        # Every design (x, then x + h e_k, then x - h e_k) goes through one `lax.map` over equal
        # vmap batches, padded with copies of x: no remainder batch and no second pipeline runs
        # beside the map. Two independent batched LAPACK calls in one XLA program (e.g. the
        # Cholesky factors of M(x + h e_k) and M(x - h e_k)) can deadlock jaxlib's CPU thread
        # pool on a 2-core machine.
        total = 2 * n + 1
        padded = -(-total // self.batch_size) * self.batch_size
        entry = jnp.concatenate([jnp.zeros(1, int), idx, idx, jnp.zeros(padded - total, int)])
        shift = jnp.concatenate([jnp.zeros(1), jnp.full(n, self.step), jnp.full(n, -self.step),
                                 jnp.zeros(padded - total)]).astype(x.dtype)

        def perturbed(k, h):
            return psi(x.at[k].add(h))

        values = jax.lax.map(lambda a: perturbed(*a), (entry, shift), batch_size=self.batch_size)
        diffs = (values[1:n + 1] - values[n + 1:2 * n + 1]) / (2 * self.step)
        grad = jnp.full_like(x, jnp.nan).at[idx].set(diffs)
        return values[0], unravel(grad)
