"""Minimal-coordinate equations of motion by coordinate partitioning (paper eqs. 10–18).

The redundant coordinates `y_r` of a [`Scene`][] are split into independent `y` and dependent
`y_d` (paper eq. 10, `B` a permutation; in the plane `Z = I`, so `z_r = dy_r/dt`). Given
`(t, y, z)`:

1. `y_d` solves `c(B[y; y_d], t, p) = 0` by Newton's method, differentiated implicitly;
2. `z_d = -C_d^-1 (C_i z + c_t)` (velocity constraints, eq. 11);
3. `zdot_r = J zdot + gammabar_r` with `J = B[I; -C_d^-1 C_i]`, `gammabar_r = B[0; -C_d^-1 gamma]`
   and `gamma = (C z_r)_y z_r + 2 C_t z_r + c_tt` (eq. 13);
4. `Mbar zdot = J^T (h_a - M gammabar_r)` with `Mbar = J^T M J` (eqs. 15–18).
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import scipy.linalg

from ._scene._scene import Scene


class Partition(eqx.Module):
    """Static split of the redundant coordinates into independent and dependent ones (paper eq. 10)."""

    independent: tuple[int, ...] = eqx.field(static=True)
    dependent: tuple[int, ...] = eqx.field(static=True)

    @property
    def n_independent(self) -> int:
        return len(self.independent)


def choose_partition(scene: Scene, t0, y_r0, prefer_dependent: tuple[int, ...] = ()) -> Partition:
    """Choose the dependent coordinates from the constraint Jacobian at the initial state.

    QR factorisation with column pivoting of `C = dc/dy_r` (Wehage and Haug 1982) picks the
    `n_c` best-conditioned columns as dependent coordinates. Columns in `prefer_dependent` are
    tried first (e.g. rigid-body coordinates) when they alone have full rank.

    Raises `ValueError` when `C` does not have full row rank (redundant or contradictory
    constraints, or a singular initial configuration).
    """
    c = np.asarray(jax.jacfwd(scene.constraint_residual, argnums=1)(jnp.asarray(t0, float), jnp.asarray(y_r0)))
    n_c, n = c.shape
    if n_c == 0:
        return Partition(independent=tuple(range(n)), dependent=())
    _, r, piv = scipy.linalg.qr(c, pivoting=True, mode="economic")
    diag = np.abs(np.diag(r))
    if diag.size < n_c or diag[-1] <= 1e-10 * max(diag[0], 1.0):
        raise ValueError(
            f"The constraint Jacobian at the initial state has rank below the number of constraints "
            f"({n_c}): the constraints are redundant or the initial configuration is singular "
            f"(singular values of C: {np.linalg.svd(c, compute_uv=False)})."
        )
    dependent = [int(i) for i in piv[:n_c]]
    if prefer_dependent and len(prefer_dependent) >= n_c:
        trial = list(prefer_dependent[:n_c])
        if np.linalg.matrix_rank(c[:, trial], tol=1e-8 * np.abs(c).max()) == n_c:
            dependent = trial
    dependent = tuple(sorted(dependent))
    independent = tuple(i for i in range(n) if i not in dependent)
    return Partition(independent=independent, dependent=dependent)


def _zeros_for_none(primals, tangents):
    """Materialise symbolic-zero tangents (`None`) of inexact arrays as zeros."""
    return jtu.tree_map(
        lambda p, t: jnp.zeros_like(p) if (t is None and eqx.is_inexact_array(p)) else t,
        primals,
        tangents,
        is_leaf=lambda x: x is None,
    )


class MinimalModel(eqx.Module):
    """Equations of motion of a [`Scene`][] in minimal coordinates `(y, z)` (paper eqs. 14–18).

    - `partition`: static split of the coordinates.
    - `dependent_guess`: `(t, y, scene) -> y_d` starting point of Newton's method (for loops a
      rigid-body estimate of the same assembly branch); default: `y_d` of the initial state.
    - `reference_dependent`: `y_d` at the initial state.
    - `newton_iterations`, `newton_tol`: at most this many iterations; converged when the update
      falls below `newton_tol * (1 + |y_d|)`.
    """

    partition: Partition
    reference_dependent: jnp.ndarray
    dependent_guess: Callable | None = eqx.field(static=True, default=None)
    newton_iterations: int = eqx.field(static=True, default=25)
    newton_tol: float = eqx.field(static=True, default=1e-13)

    # --- coordinates -------------------------------------------------------------------------
    def assemble(self, y, y_d):
        """`y_r = B [y; y_d]` (along the leading axis; trailing axes are carried along)."""
        n = len(self.partition.independent) + len(self.partition.dependent)
        out = jnp.zeros((n,) + y.shape[1:], jnp.result_type(y, y_d))
        out = out.at[np.asarray(self.partition.independent, int)].set(y)
        return out.at[np.asarray(self.partition.dependent, int)].set(y_d)

    def split(self, v_r):
        """`v_r -> (v, v_d)`."""
        return v_r[np.asarray(self.partition.independent, int)], v_r[np.asarray(self.partition.dependent, int)]

    # --- position level ----------------------------------------------------------------------
    def dependent_positions(self, t, y, scene: Scene):
        """`y_d(t, y, p)` solving `c(B[y; y_d], t, p) = 0` (Newton; implicit derivative)."""
        if not self.partition.dependent:
            return jnp.zeros((0,), y.dtype)
        return _solve_dependent(self, jnp.asarray(t, dtype=y.dtype), y, scene)

    def positions(self, t, y, scene: Scene):
        return self.assemble(y, self.dependent_positions(t, y, scene))

    # --- velocity and acceleration level -----------------------------------------------------
    def constraint_jacobian(self, t, y_r, scene: Scene):
        """`C = dc/dy_r`, `(n_c, n_r)`."""
        return jax.jacfwd(scene.constraint_residual, argnums=1)(t, y_r)

    def velocity_constraint(self, t, y_r, z_r, scene: Scene):
        """`cdot = C z_r + c_t` (paper eq. 11)."""
        return jax.jvp(scene.constraint_residual, (t, y_r), (jnp.ones_like(t), z_r))[1]

    def velocities(self, t, y_r, z, scene: Scene):
        """`z_r = B [z; z_d]` with `z_d = -C_d^-1 (C_i z + c_t)`."""
        if not self.partition.dependent:
            return z
        c = self.constraint_jacobian(t, y_r, scene)
        _, c_d = self.split(c.T)
        b = self.velocity_constraint(t, y_r, self.assemble(z, jnp.zeros(len(self.partition.dependent), z.dtype)), scene)
        return self.assemble(z, -jnp.linalg.solve(c_d.T, b))

    def minimal_terms(self, t, y_r, z_r, scene: Scene):
        """`(Mbar, fbar - gammabar)` of paper eq. 15 as functions of the redundant state.

        `Mbar = J^T M J` and `J^T (h_a - M gammabar_r)` with `J`, `gammabar_r` of eq. 13.
        """
        m = scene.mass_matrix(y_r)
        h = scene.applied_forces(t, y_r, z_r)
        if not self.partition.dependent:
            return m, h
        c = self.constraint_jacobian(t, y_r, scene)
        c_i, c_d = self.split(c.T)
        c_i, c_d = c_i.T, c_d.T
        gamma = jax.jvp(
            lambda tt, yy: self.velocity_constraint(tt, yy, z_r, scene), (t, y_r), (jnp.ones_like(t), z_r)
        )[1]
        lu = jax.scipy.linalg.lu_factor(c_d)
        dep_j = -jax.scipy.linalg.lu_solve(lu, c_i)
        dep_gamma = -jax.scipy.linalg.lu_solve(lu, gamma)
        f = len(self.partition.independent)
        jac = self.assemble(jnp.eye(f), dep_j)  # (n_r, f)
        gamma_r = self.assemble(jnp.zeros(f, gamma.dtype), dep_gamma)
        return jac.T @ m @ jac, jac.T @ (h - m @ gamma_r)

    def accelerations(self, t, y_r, z_r, scene: Scene):
        """`zdot = Mbar^-1 (fbar - gammabar)` (paper eq. 15)."""
        mbar, rhs = self.minimal_terms(t, y_r, z_r, scene)
        return jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(mbar), rhs)

    def state(self, t, y, z, scene: Scene):
        """Redundant positions and velocities `(y_r, z_r)` of the minimal state `(y, z)`."""
        y_r = self.positions(t, y, scene)
        return y_r, self.velocities(t, y_r, z, scene)

    def vector_field(self, t, y, z, scene: Scene):
        """`(ydot, zdot)` of the minimal equations of motion (paper eqs. 14–15)."""
        y_r, z_r = self.state(t, y, z, scene)
        return z, self.accelerations(t, y_r, z_r, scene)


def _newton(model: MinimalModel, t, y, scene: Scene):
    """Primal Newton iteration for `y_d`, with convergence and regularity checks."""
    guess = model.reference_dependent if model.dependent_guess is None else model.dependent_guess(t, y, scene)
    guess = jnp.asarray(guess, dtype=y.dtype)

    def residual(y_d):
        return scene.constraint_residual(t, model.assemble(y, y_d))

    def body(carry):
        y_d, _, k = carry
        step = jnp.linalg.solve(jax.jacfwd(residual)(y_d), residual(y_d))
        return y_d - step, jnp.max(jnp.abs(step)), k + 1

    def cond(carry):
        y_d, size, k = carry
        return (k < model.newton_iterations) & (size > model.newton_tol * (1.0 + jnp.max(jnp.abs(y_d))))

    y_d, _, _ = jax.lax.while_loop(cond, body, (guess, jnp.asarray(jnp.inf, y.dtype), 0))
    # Judge regularity where Newton ended, or at its start if it blew up; a NaN there (a NaN guess)
    # is a convergence failure, not a singular partition.
    c_d = jax.jacfwd(residual)(jnp.where(jnp.all(jnp.isfinite(y_d)), y_d, guess))
    scale = 1.0 + jnp.max(jnp.abs(model.assemble(y, y_d)))
    hadamard = jnp.abs(jnp.linalg.det(c_d)) / jnp.maximum(jnp.prod(jnp.linalg.norm(c_d, axis=1)), 1e-300)
    y_d = eqx.error_if(
        y_d,
        hadamard <= 1e-9,
        "The coordinate partition became singular: the constraint Jacobian with respect to the "
        "dependent coordinates lost rank along the motion (e.g. a linkage at a dead point). "
        "Choose another partition (MinimalModel(partition=...)), or stop the simulation earlier.",
    )
    y_d = eqx.error_if(
        y_d,
        ~(jnp.max(jnp.abs(residual(y_d))) <= 1e-9 * scale),
        "Newton's method for the dependent coordinates did not converge: the position constraints "
        "have no solution near the starting guess (the mechanism cannot assemble, or the guess is "
        "on another branch). Check the scene geometry or give a better dependent_guess.",
    )
    return y_d


@eqx.filter_custom_jvp
def _solve_dependent(model, t, y, scene):
    return _newton(model, t, y, scene)


@_solve_dependent.def_jvp
def _solve_dependent_jvp(primals, tangents):
    model, t, y, scene = primals
    _, dt, dy, dscene = _zeros_for_none(primals, tangents)
    y_d = _newton(model, t, y, scene)

    def residual(t_, y_, scene_):
        return scene_.constraint_residual(t_, model.assemble(y_, y_d))

    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    ddyn, _ = eqx.partition(dscene, eqx.is_inexact_array)
    _, dres = jax.jvp(
        lambda t_, y_, dyn_: residual(t_, y_, eqx.combine(dyn_, static)), (t, y, dyn), (dt, dy, ddyn)
    )
    c_d = jax.jacfwd(lambda yd: scene.constraint_residual(t, model.assemble(y, yd)))(y_d)
    return y_d, -jnp.linalg.solve(c_d, dres)
