"""Finite differences in the design variables: central inside the bounds, one-sided at them."""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from .._checks import integer, is_traced, positive
from ._base import AbstractSensitivity, psi_of


def _entries(entries) -> tuple[int, ...] | None:
    """`None`, or the design indices as a non-empty tuple of Python ints `>= 0`."""
    if entries is None:
        return None
    try:
        entries = tuple(entries)
    except TypeError:
        raise ValueError(f"FiniteDifferences(entries=...) must be a sequence of design indices, got {entries!r}.") \
            from None
    if not entries:
        raise ValueError("FiniteDifferences(entries=()) selects no design variable; leave entries=None for all.")
    return tuple(integer(k, "FiniteDifferences(entries=...): every index", 0) for k in entries)


def _lower_bounds(case, x):
    """`x_min` of every design variable, in the form of `x` (a dict by body, or one body's array), as
    NumPy arrays (known at trace time: the shapes are static and `x_min` is a Python float)."""
    bodies = getattr(case.design_map, "bodies", None)
    if isinstance(x, dict) and bodies is not None:
        return {name: np.full(jnp.shape(value), bodies[name].material.x_min) for name, value in x.items()}
    return np.full(jnp.shape(x), case.material.x_min)


# The smallest step, in units of the forward rtol. psi of each solve has a relative error of about rtol,
# so a difference quotient carries a noise of about rtol |psi| / h (per unit density); h >= 100 rtol keeps it
# below 1 % of |psi|. (The truncation error of the central quotient, ~h^2, is smallest at h ~ rtol^(1/3);
# 1e-12 at rtol 1e-10 gave a gradient 3.6x off, issue 32.)
NOISE_FLOOR = 100.0


class FiniteDifferences(AbstractSensitivity):
    """Finite differences of `psi` in the design variables, central where the bounds allow:

    `(psi(x + u_k e_k) - psi(x - d_k e_k)) / (u_k + d_k)`, with `u_k = h` where `x_k + h <= 1`
    and `d_k = h` where `x_k - h >= x_min`, else 0. Inside the bounds this is the central
    difference (error `O(h^2)`); at a density within `h` of a bound it is the one-sided
    difference into the admissible side (error `O(h)`), so that designs with densities at
    `x_min` or 1 (voids, solids) can be differenced. Every entry costs two solves either way.

    **Fields:**
    - `step`: the perturbation `h > 0` (the paper used 0.1; a converged one is ~1e-4…1e-6, with
      the forward tolerance far below `h^2`). It must be below `(1 - x_min) / 2`, so that one side
      always fits, and at least `100 rtol` (the noise floor: each psi carries a relative error of
      about `rtol`, so the quotient carries about `rtol |psi| / h`; a smaller step is refused).
    - `entries`: optional indices of the design variables to difference (default: all); other
      entries of the returned gradient are NaN so that they cannot be mistaken for values. For a
      dict design the indices count in the flattened design (`jax.flatten_util.ravel_pytree`:
      bodies in sorted name order).
    - `batch_size`: how many perturbed designs are simulated at once (`jax.lax.map` over
      `jax.vmap` batches), an integer `>= 1`.
    """

    step: float = 1e-5
    entries: tuple[int, ...] | None = eqx.field(default=None, converter=_entries)
    batch_size: int = 8

    def __check_init__(self):
        positive(self.step, "FiniteDifferences(step=...)", "Use about 1e-4…1e-6 with forward tolerances far "
                 "below step^2.")
        integer(self.batch_size, "FiniteDifferences(batch_size=...)", 1)

    def value_and_grad_problem(self, problem, *, rtol, atol, solver, max_steps):
        raise ValueError("Finite differences act on the design, not on the problem's parameters: use "
                         "value_and_grad(case, x, 'fd'), or another method (e.g. 'adjoint') for problem gradients.")

    def value_and_grad_design(self, case, x, *, rtol, atol, solver, max_steps):
        adjoint = diffrax.RecursiveCheckpointAdjoint()
        lower = _lower_bounds(case, x)
        x, unravel = jax.flatten_util.ravel_pytree(x)
        lo, hi = np.concatenate([np.ravel(a) for a in jax.tree_util.tree_leaves(lower)]), 1.0
        widest = float(np.max(lo))
        if not self.step < (hi - widest) / 2:
            raise ValueError(f"FiniteDifferences(step={self.step}) must be below (1 - x_min) / 2 = {(hi - widest) / 2:g}, "
                             "so that every density can be perturbed to one side inside [x_min, 1].")
        if not is_traced(rtol) and self.step < NOISE_FLOOR * float(rtol):
            raise ValueError(
                f"FiniteDifferences(step={self.step:g}) is below the noise floor of the forward solves: at "
                f"rtol = {float(rtol):g} each psi carries a relative error of about rtol, so a difference quotient "
                f"carries about rtol |psi| / step = {float(rtol) / self.step:.3g} |psi| of noise per unit density. "
                f"Use a step of at least {NOISE_FLOOR:g} rtol = {NOISE_FLOOR * float(rtol):g} (about 1e-4 to 1e-6 with "
                "the default rtol 1e-10), or a tighter rtol."
            )
        if self.entries is not None and max(self.entries) >= x.size:
            raise ValueError(f"FiniteDifferences(entries=...) holds index {max(self.entries)}, but the design has "
                             f"{x.size} variables (indices 0 to {x.size - 1}).")

        def psi(xx):
            return psi_of(case.problem.with_scene(case.scene(unravel(xx))), rtol=rtol, atol=atol, solver=solver,
                          max_steps=max_steps, adjoint=adjoint)

        idx = jnp.arange(x.size) if self.entries is None else jnp.asarray(self.entries, int)
        n = idx.size
        # Central where x_k +- h stays inside [x_min, 1], one-sided into the admissible side where not.
        # Since h < (1 - x_min) / 2, at least one side fits, so up + down >= h > 0.
        up = jnp.where(x[idx] + self.step <= hi, self.step, 0.0).astype(x.dtype)
        down = jnp.where(x[idx] - self.step >= jnp.asarray(lo)[idx], self.step, 0.0).astype(x.dtype)
        # Every design (x, then x + u_k e_k, then x - d_k e_k) goes through one `lax.map` over equal
        # vmap batches, padded with copies of x: no remainder batch and no second pipeline runs
        # beside the map. Two independent batched LAPACK calls in one XLA program (e.g. the
        # Cholesky factors of M(x + h e_k) and M(x - h e_k)) can deadlock jaxlib's CPU thread
        # pool on a 2-core machine.
        total = 2 * n + 1
        padded = -(-total // self.batch_size) * self.batch_size
        entry = jnp.concatenate([jnp.zeros(1, int), idx, idx, jnp.zeros(padded - total, int)])
        shift = jnp.concatenate([jnp.zeros(1, x.dtype), up, -down, jnp.zeros(padded - total, x.dtype)])

        def perturbed(k, h):
            return psi(x.at[k].add(h))

        values = jax.lax.map(lambda a: perturbed(*a), (entry, shift), batch_size=self.batch_size)
        diffs = (values[1:n + 1] - values[n + 1:2 * n + 1]) / (up + down)
        grad = jnp.full_like(x, jnp.nan).at[idx].set(diffs)
        return values[0], unravel(grad)
