"""A cheap guard on a design gradient: its directional derivative against a central difference.

Every gradient method differentiates a discrete solution. Where the step-size controller sits at
the stability limit of an explicit solver (many retained modes), the derivative of the discrete
solution computed by `jax.grad` through the solver can differ from the derivative of the solution
(issue 15: at 20 modes autodiff through Dopri8 at rtol 1e-10 returned max|g| = 8.77e-6 with wrong
signs, where finite differences, the adjoint and backsolve agreed on 1.475e-8). This check costs
two forward solves per direction and tells such a gradient from a trustworthy one.
"""

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from collections.abc import Callable


class GradientCheck(eqx.Module):
    """The result of [`check_gradient`][] (one entry per direction checked).

    - `directional`: `grad . d` of the gradient under test along each unit direction `d`.
    - `finite_difference`: `(psi(x + h d) - psi(x - h d)) / (2 h)` along the same directions.
    - `error`: `|directional - finite_difference| / max|finite_difference|, |directional|)`.
    - `tolerance`: the largest `error` accepted; `trusted`: every `error <= tolerance`.
    """

    directional: np.ndarray
    finite_difference: np.ndarray
    error: np.ndarray
    tolerance: float
    trusted: bool

    def message(self) -> str:
        """A sentence stating the check's result."""
        pairs = ", ".join(f"{a:.6e} vs {b:.6e}" for a, b in zip(self.directional, self.finite_difference))
        if self.trusted:
            return (f"Gradient check passed: directional derivatives (gradient vs central difference) {pairs}; "
                    f"largest relative difference {float(np.max(self.error)):.1e} <= {self.tolerance:g}.")
        return (f"Untrustworthy gradient: its directional derivative disagrees with a central difference of psi "
                f"({pairs}; relative difference {float(np.max(self.error)):.1e} > {self.tolerance:g}). The derivative "
                "of the discrete solution is not that of the solution (e.g. autodiff through an explicit solver at "
                "its stability limit with many modes): use method='adjoint' or 'backsolve', a stiff solver "
                "(ffr_jax.Rodas5P()), or a tighter rtol.")


def compare_with_differences(psi: Callable, x, grad, *, lower: float, step: float, tolerance: float,
                             random_directions: int, seed: int) -> GradientCheck:
    """The check of [`check_gradient`][ffr_jax.check_gradient] with `psi(x)` given as a function (the
    forward solve) and `lower` the smallest density the design may take."""

    flat_x, unravel = jax.flatten_util.ravel_pytree(x)
    flat_g = jax.flatten_util.ravel_pytree(grad)[0]
    flat_x, flat_g = np.asarray(flat_x, float), np.asarray(flat_g, float)
    if flat_g.shape != flat_x.shape:
        raise ValueError(f"check_gradient: the gradient has {flat_g.size} entries but the design {flat_x.size}.")
    if not np.all(np.isfinite(flat_g)):
        raise ValueError("check_gradient: the gradient has NaN or infinite entries (finite differences on some "
                         "entries only?); check a complete gradient.")
    inside = (flat_x - step >= lower) & (flat_x + step <= 1.0)
    rng = np.random.default_rng(seed)
    directions = [flat_g] + [rng.standard_normal(flat_x.size) for _ in range(random_directions)]
    directional, differences = [], []
    for d in directions:
        d = np.where(inside, d, 0.0)
        norm = np.linalg.norm(d)
        if norm == 0.0:
            raise ValueError("check_gradient: the direction is zero on every entry that can move by the step "
                             "inside [x_min, 1] (a zero gradient, or a design at its bounds): nothing to check.")
        d = d / norm
        plus = float(psi(unravel(jnp.asarray(flat_x + step * d))))
        minus = float(psi(unravel(jnp.asarray(flat_x - step * d))))
        directional.append(float(flat_g @ d))
        differences.append((plus - minus) / (2.0 * step))
    directional, differences = np.asarray(directional), np.asarray(differences)
    scale = np.maximum(np.abs(directional), np.abs(differences))
    error = np.abs(directional - differences) / np.where(scale > 0.0, scale, 1.0)
    return GradientCheck(directional=directional, finite_difference=differences, error=error,
                         tolerance=float(tolerance), trusted=bool(np.all(error <= tolerance)))
