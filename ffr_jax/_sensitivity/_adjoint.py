"""The adjoint variable method of the paper (Sect. 3), integrated backward with diffrax."""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from .._case import FlexibleRodCase
from .._scene._scene import Scene
from .._simulate import simulate
from .._small_linalg import lu_factor, lu_solve, matmul, spd_solve
from ._base import AbstractSensitivity


class AdjointTerms(eqx.Module):
    """The matrices of paper eqs. 25, 30, 33 at one time, plus what the adjoint ODE needs.

    `R1` `(f,)`, `S1`, `S2`, `T1`, `T2` `(f, f)`, `Mbar`, `Mbar_dot` `(f, f)`; the design terms
    `R2`, `S3`, `T3` are never formed (see [`design_term`][]).
    """

    r1: jnp.ndarray
    s1: jnp.ndarray
    s2: jnp.ndarray
    t1: jnp.ndarray
    t2: jnp.ndarray
    mbar: jnp.ndarray
    mbar_dot: jnp.ndarray


def _redundant_functions(case: FlexibleRodCase, t, zdot):
    """The paper's functions of `(y_r, z_r, p)` at fixed `t` and `zdot`: `c`, `cdot`, `v`, `ODE`, `F`."""
    model = case.model

    def c(y_r, scene):
        return scene.constraint_residual(t, y_r)

    def cdot(y_r, z_r, scene):
        return model.velocity_constraint(t, y_r, z_r, scene)

    def v(y_r, z_r):
        return model.split(z_r)[0]

    def ode(y_r, z_r, scene):
        mbar, rhs = model.minimal_terms(t, y_r, z_r, scene)
        return matmul(mbar, zdot) - rhs

    def f(y_r, scene):
        return case.integrand(t, y_r, scene)

    return c, cdot, v, ode, f


def _state(case, t, y, z, scene):
    return case.model.state_and_accelerations(t, y, z, scene)


def adjoint_terms(case: FlexibleRodCase, t, y, z, scene: Scene):
    """`R1, S1, S2, T1, T2, Mbar, dMbar/dt` at `(t, y, z)` (paper eqs. 25, 30, 33).

    All partial derivatives with respect to the redundant coordinates come from `jax.jacfwd`;
    the variations of the dependent coordinates are eliminated with the position and velocity
    constraints exactly as in the paper (eqs. 23, 28):
    `dy_d/dy = -c_yd^-1 c_y`, `dz_d/dy = -cdot_zd^-1 (cdot_y + cdot_yd dy_d/dy)`,
    `dz_d/dz = -cdot_zd^-1 cdot_z`.

    Also returns the redundant state and the elimination factors used by [`design_term`][].
    """
    model = case.model
    ind = np.asarray(model.partition.independent, int)
    dep = np.asarray(model.partition.dependent, int)
    y_r, z_r, zdot = _state(case, t, y, z, scene)
    c, cdot, v, ode, f = _redundant_functions(case, t, zdot)

    c_y = jax.jacfwd(c)(y_r, scene)
    cd_y, cd_z = jax.jacfwd(cdot, argnums=(0, 1))(y_r, z_r, scene)
    v_y, v_z = jax.jacfwd(v, argnums=(0, 1))(y_r, z_r)
    o_y, o_z = jax.jacfwd(ode, argnums=(0, 1))(y_r, z_r, scene)
    f_y = jax.grad(f)(y_r, scene)

    if dep.size:
        lu_c = lu_factor(c_y[:, dep])
        lu_cd = lu_factor(cd_z[:, dep])
        dyd_dy = -lu_solve(lu_c, c_y[:, ind])
        dzd_dy = -lu_solve(lu_cd, cd_y[:, ind] + matmul(cd_y[:, dep], dyd_dy))
        dzd_dz = -lu_solve(lu_cd, cd_z[:, ind])
        s1 = -(v_y[:, ind] + matmul(v_y[:, dep], dyd_dy) + matmul(v_z[:, dep], dzd_dy))
        s2 = -(v_z[:, ind] + matmul(v_z[:, dep], dzd_dz))
        t1 = o_y[:, ind] + matmul(o_y[:, dep], dyd_dy) + matmul(o_z[:, dep], dzd_dy)
        t2 = o_z[:, ind] + matmul(o_z[:, dep], dzd_dz)
        r1 = f_y[ind] + matmul(dyd_dy.T, f_y[dep])
    else:
        lu_c = lu_cd = None
        s1, s2 = -v_y[:, ind], -v_z[:, ind]
        t1, t2 = o_y[:, ind], o_z[:, ind]
        r1 = f_y[ind]

    def mbar_fn(tt, yy):
        return model.minimal_terms(tt, yy, z_r, scene)[0]

    mbar, mbar_dot = jax.jvp(mbar_fn, (t, y_r), (jnp.ones_like(t), z_r))
    terms = AdjointTerms(r1=r1, s1=s1, s2=s2, t1=t1, t2=t2, mbar=mbar, mbar_dot=mbar_dot)
    partials = (v_y, v_z, o_y, o_z, f_y, cd_y, lu_c, lu_cd)
    return terms, (y_r, z_r, zdot), partials


def design_term(case: FlexibleRodCase, t, state, partials, scene: Scene, mu, nu):
    """`R2 - mu^T S3 - nu^T T3` (the integrand of paper eq. 44) as a pytree like `scene`.

    With the dependent variations eliminated (eqs. 23, 28) this is
    `F_p - nu^T ODE_p - b^T cdot_p - e^T c_p` where
    `b^T = (mu^T v_zd - nu^T ODE_zd) cdot_zd^-1` and
    `e^T = (F_yd + mu^T v_yd - nu^T ODE_yd - b^T cdot_yd) c_yd^-1`:
    one `jax.vjp` of `(F, ODE, cdot, c)` with respect to `p`, whatever the number of parameters.
    """
    model = case.model
    dep = np.asarray(model.partition.dependent, int)
    y_r, z_r, zdot = state
    v_y, v_z, o_y, o_z, f_y, cd_y, lu_c, lu_cd = partials
    c, cdot, _, ode, f = _redundant_functions(case, t, zdot)
    if dep.size:
        a_z = matmul(v_z[:, dep].T, mu) - matmul(o_z[:, dep].T, nu)
        b = lu_solve(lu_cd, a_z, trans=1)
        a_y = f_y[dep] + matmul(v_y[:, dep].T, mu) - matmul(o_y[:, dep].T, nu) - matmul(cd_y[:, dep].T, b)
        e = lu_solve(lu_c, a_y, trans=1)
    else:
        b = e = jnp.zeros((0,), mu.dtype)

    dyn, static = eqx.partition(scene, eqx.is_inexact_array)

    def all_terms(dyn_):
        s = eqx.combine(dyn_, static)
        return f(y_r, s), ode(y_r, z_r, s), cdot(y_r, z_r, s), c(y_r, s)

    _, pullback = jax.vjp(all_terms, dyn)
    (g,) = pullback((jnp.ones_like(f_y[0]), -nu, -b, -e))
    return g


class Adjoint(AbstractSensitivity):
    """The adjoint variable method of the paper (Sect. 3.2), backward in diffrax.

    Forward: the minimal equations of motion with dense output. Backward, from `t1` to `t0`
    (paper eq. 43, final values `mu(t1) = 0`, `Mbar(t1) nu(t1) = 0`):

    `mu' = S1^T mu + T1^T nu - R1^T`,  `Mbar nu' = S2^T mu - Mbar' nu + T2^T nu`,

    together with the gradient (paper eq. 44) `G' = -(R2 - mu^T S3 - nu^T T3)`, `G(t1) = 0`,
    `grad psi = G(t0)`, accumulated in the parameter space `p` (the body data and scene
    parameters, a few hundred numbers) so that the cost does not grow with the number of design
    variables; one VJP of `p(x)` then gives the design gradient.

    **Fields:** `rtol`, `atol` of the backward solve (the paper's 1e-8 / 1e-10 by default), and
    the backward `solver` (default: the forward solver).

    !!! cite "Reference"
        Held, Knüfer, Seifried (2017). Structural sensitivity analysis of flexible multibody
        systems modeled with the floating frame of reference approach using the adjoint
        variable method. Multibody System Dynamics.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    solver: diffrax.AbstractSolver | None = None

    def value_and_grad_scene(self, case, scene, *, rtol, atol, solver, max_steps):
        forward = simulate(
            case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
            solver=solver, rtol=rtol, atol=atol, dense=True, max_steps=max_steps, jump_ts=case.jump_ts,
        )
        dense = forward.solution
        dyn, _ = eqx.partition(scene, eqx.is_inexact_array)
        flat, unravel = jax.flatten_util.ravel_pytree(dyn)
        f = case.model.partition.n_independent

        def field(t, state, args):
            mu, nu, _ = state
            y, z = dense.evaluate(t)[:2]
            terms, red, partials = adjoint_terms(case, t, y, z, scene)
            mu_dot = matmul(terms.s1.T, mu) + matmul(terms.t1.T, nu) - terms.r1
            nu_dot = spd_solve(terms.mbar, matmul(terms.s2.T, mu) - matmul(terms.mbar_dot, nu) + matmul(terms.t2.T, nu))
            g = design_term(case, t, red, partials, scene, mu, nu)
            return mu_dot, nu_dot, -jax.flatten_util.ravel_pytree(g)[0]

        zeros = jnp.zeros(f)
        state1 = (zeros, zeros, jnp.zeros_like(flat))
        backward_solver = (solver if solver is not None else diffrax.Tsit5()) if self.solver is None else self.solver
        jumps = tuple(j for j in case.jump_ts if case.t0 < j < case.t1)
        controller = diffrax.PIDController(rtol=self.rtol, atol=self.atol, jump_ts=jnp.asarray(jumps) if jumps else None)
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field), backward_solver, case.t1, case.t0, None, state1,
            stepsize_controller=controller, saveat=diffrax.SaveAt(t1=True), max_steps=max_steps,
            adjoint=diffrax.RecursiveCheckpointAdjoint(),
        )
        return forward.psi, unravel(sol.ys[2][-1])
