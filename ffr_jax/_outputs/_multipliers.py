"""Lagrange multipliers of the constraints recovered from the minimal-coordinate solution."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from .._dynamics._model import MinimalModel, _zeros_for_none
from .._dynamics._small_linalg import LU, BlockLU, lu_factor, lu_solve, matmul, spd_solve
from .._scene._scene import Scene


def constraint_multipliers(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`(zdot_r, lambda)`: redundant accelerations and the multipliers of every constraint equation.

    The redundant equations of motion `M(y_r) zdot_r + C^T lambda = h_a(t, y_r, z_r)` (paper eqs.
    8–9) hold on their independent rows by the minimal equations (eq. 15, `J^T C^T = 0`); their
    dependent rows give the multipliers,

    `lambda = C_d^-T (h_a - M zdot_r)_d`,

    with `zdot_r = J zdot + gammabar_r` (eq. 13), `J = B[I; -C_d^-1 C_i]`, and `zdot = Mbar^-1 (fbar -
    gammabar)` (eq. 15). `-C^T lambda` is the generalized force the joints and drivers exert
    on the bodies. A pure function of the state and the scene: every sensitivity method differentiates
    it.

    `(zdot_r, lambda)` solves the augmented system `[M C^T; C 0] [zdot_r; lambda] = [h_a; -gamma]`, and
    is differentiated as its solution (implicit function theorem): the tangent solves the same
    system, with the factors of `C_d` and `Mbar` already formed, for the right-hand side `-dR` of the
    residual `R = [M zdot_r + C^T lambda - h_a; C zdot_r + gamma]` at the fixed solution. Reverse
    mode then transposes one linear solve and one tangent of `R` (a product with the mass matrix, the
    applied forces and derivatives of the constraints) instead of the factorisations, the Jacobian
    and the nested derivatives that form `zdot_r` and `lambda` (issue 31: that made a gradient of a
    [`JointLoad`][] compile for minutes).

    **Returns:** `zdot_r` `(n_r,)` and `lambda` `(n_c,)`, ordered as `scene.constraints`.
    """
    t = jnp.asarray(t, dtype=y_r.dtype)
    if not model.partition.dependent:
        return model.accelerations(t, y_r, z_r, scene), jnp.zeros((0,), y_r.dtype)
    return _multipliers(model, t, y_r, z_r, scene)


class _Augmented(eqx.Module):
    """The augmented matrix `A = [M C^T; C 0]` of a consistent state through its factors: `M`, `C_i`,
    the factors of `C_d` and `Mbar = J^T M J`, and `D = -C_d^-1 C_i` (the dependent rows of `J`)."""

    m: jax.Array
    c_i: jax.Array
    lu_d: LU | BlockLU
    lu_bar: LU
    d: jax.Array

    def solve(self, model: MinimalModel, a, b):
        """`(x, l)` with `M x + C^T l = a`, `C x = b`: `x = J u + x_p` with `x_p = B [0; C_d^-1 b]`,
        `Mbar u = J^T (a - M x_p)`, and `l = C_d^-T (a - M x)_d`. Linear in `(a, b)` (for transposition)."""
        f = self.d.shape[1]
        x_pd = lu_solve(self.lu_d, b)
        residual = a - matmul(self.m, model.assemble(jnp.zeros(f, x_pd.dtype), x_pd))
        r_i, r_d = model.split(residual)
        u = lu_solve(self.lu_bar, r_i + matmul(self.d.T, r_d))
        x = model.assemble(u, matmul(self.d, u) + x_pd)
        return x, lu_solve(self.lu_d, model.split(a - matmul(self.m, x))[1], trans=1)


def _gamma(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`gamma = (C z_r)_y z_r + 2 C_t z_r + c_tt` (paper eq. 13): `C zdot_r + gamma = 0` on the motion."""
    return jax.jvp(lambda tt, yy: model.velocity_constraint(tt, yy, z_r, scene), (t, y_r), (jnp.ones_like(t), z_r))[1]


def _solution(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`(zdot_r, lambda)` and the factors of the augmented matrix, in one pass over the scene."""
    c_i, _, lu_d = model._velocity_level(t, y_r, scene)
    m = scene.mass_matrix(y_r)
    h = scene.applied_forces(t, y_r, z_r)
    f = len(model.partition.independent)
    dep = -lu_solve(lu_d, jnp.concatenate([c_i, _gamma(model, t, y_r, z_r, scene)[:, None]], axis=1))
    jac = model.assemble(jnp.eye(f, dtype=dep.dtype), dep[:, :f])  # J of eq. 13, (n_r, f)
    gamma_r = model.assemble(jnp.zeros(f, dep.dtype), dep[:, f])
    m_jac = matmul(m, jac)
    mbar = matmul(jac.T, m_jac)
    zdot = spd_solve(mbar, matmul(jac.T, h) - matmul(m_jac.T, gamma_r))  # paper eq. 15
    zdot_r = matmul(jac, zdot) + gamma_r
    lam = lu_solve(lu_d, model.split(h - matmul(m, zdot_r))[1], trans=1)
    return (zdot_r, lam), _Augmented(m=m, c_i=c_i, lu_d=lu_d, lu_bar=lu_factor(mbar), d=dep[:, :f])


def _residual(model: MinimalModel, zdot_r, lam):
    """`R(t, y_r, z_r, scene) = [M zdot_r + C^T lambda - h_a; C zdot_r + gamma]` at fixed `(zdot_r, lambda)`;
    `C zdot_r + gamma` is the second time derivative of `c` along `(t, y_r, z_r, zdot_r)`."""

    def residual(t, y_r, z_r, scene):
        c_t_lam = jax.vjp(lambda y: scene.constraint_residual(t, y), y_r)[1](lam)[0]
        forces = matmul(scene.mass_matrix(y_r), zdot_r) + c_t_lam - scene.applied_forces(t, y_r, z_r)
        acceleration = jax.jvp(lambda tt, yy, zz: model.velocity_constraint(tt, yy, zz, scene), (t, y_r, z_r),
                               (jnp.ones_like(t), z_r, zdot_r))[1]
        return forces, acceleration

    return residual


@eqx.filter_custom_jvp
def _multipliers(model, t, y_r, z_r, scene):
    return _solution(model, t, y_r, z_r, scene)[0]


@_multipliers.def_jvp
def _multipliers_jvp(primals, tangents):
    model, t, y_r, z_r, scene = primals
    (zdot_r, lam), augmented = _solution(model, t, y_r, z_r, scene)
    residual = _residual(model, zdot_r, lam)
    if all(leaf is None for leaf in jtu.tree_leaves(tangents[4], is_leaf=lambda x: x is None)):
        # No scene tangent (a Jacobian with respect to the state): the scene stays a constant, as in
        # `_state_and_accelerations_jvp`, rather than carrying materialised zero tangents of its body data.
        _, dt, dy, dz = _zeros_for_none(primals[:4], tangents[:4])
        d_forces, d_acceleration = jax.jvp(lambda a, b, c: residual(a, b, c, scene), (t, y_r, z_r), (dt, dy, dz))[1]
    else:
        _, dt, dy, dz, dscene = _zeros_for_none(primals, tangents)
        dyn, static = eqx.partition(scene, eqx.is_inexact_array)
        ddyn, _ = eqx.partition(dscene, eqx.is_inexact_array)
        d_forces, d_acceleration = jax.jvp(lambda a, b, c, d: residual(a, b, c, eqx.combine(d, static)),
                                           (t, y_r, z_r, dyn), (dt, dy, dz, ddyn))[1]
    return (zdot_r, lam), augmented.solve(model, -d_forces, -d_acceleration)
