"""The adjoint variable method of the paper (Sect. 3), integrated backward with diffrax.

The backward solve carries only the adjoint variables `(mu, Mbar nu)` (paper eq. 43); the gradient
integral of paper eq. 44 is evaluated afterwards by Gauss–Legendre quadrature on the accepted
backward steps, all nodes at once (see [`Adjoint`][]).
"""

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
    `R2`, `S3`, `T3` are never formed (see [`adjoint_products`][]).
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
        return matmul(mbar, zdot) - rhs, mbar

    def f(y_r, scene):
        return case.integrand(t, y_r, scene)

    return c, cdot, v, ode, f


def adjoint_terms(case: FlexibleRodCase, t, y, z, scene: Scene) -> AdjointTerms:
    """`R1, S1, S2, T1, T2, Mbar, dMbar/dt` at `(t, y, z)` as matrices (paper eqs. 25, 30, 33).

    All partial derivatives with respect to the redundant coordinates come from `jax.jacfwd`;
    the variations of the dependent coordinates are eliminated with the position and velocity
    constraints exactly as in the paper (eqs. 23, 28):
    `dy_d/dy = -c_yd^-1 c_y`, `dz_d/dy = -cdot_zd^-1 (cdot_y + cdot_yd dy_d/dy)`,
    `dz_d/dz = -cdot_zd^-1 cdot_z`.

    The adjoint solve uses the products of these matrices with `(mu, nu)` instead
    ([`adjoint_products`][], the same numbers without forming the matrices); this form states the
    paper's terms one by one and checks the products in the tests.
    """
    model = case.model
    ind = np.asarray(model.partition.independent, int)
    dep = np.asarray(model.partition.dependent, int)
    y_r, z_r, zdot = model.state_and_accelerations(t, y, z, scene)
    c, cdot, v, ode, f = _redundant_functions(case, t, zdot)

    c_y = jax.jacfwd(c)(y_r, scene)
    cd_y, cd_z = jax.jacfwd(cdot, argnums=(0, 1))(y_r, z_r, scene)
    v_y, v_z = jax.jacfwd(v, argnums=(0, 1))(y_r, z_r)
    o_y, o_z = jax.jacfwd(lambda a, b: ode(a, b, scene)[0], argnums=(0, 1))(y_r, z_r)
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
        s1, s2 = -v_y[:, ind], -v_z[:, ind]
        t1, t2 = o_y[:, ind], o_z[:, ind]
        r1 = f_y[ind]

    def mbar_fn(tt, yy):
        return model.minimal_terms(tt, yy, z_r, scene)[0]

    mbar, mbar_dot = jax.jvp(mbar_fn, (t, y_r), (jnp.ones_like(t), z_r))
    return AdjointTerms(r1=r1, s1=s1, s2=s2, t1=t1, t2=t2, mbar=mbar, mbar_dot=mbar_dot)


def adjoint_products(case: FlexibleRodCase, t, y, z, scene: Scene, mu, w, *, design: bool = False):
    """The terms of paper eqs. 43–44 at `(t, y, z)` as products with the adjoint variables, by reverse mode.

    The adjoint variables are `mu` and `w = Mbar nu`; `nu = Mbar^-1 w`. With
    `Phi(y_r, z_r, p) = nu^T ODE - mu^T v - F` (`ODE = Mbar zdot - (fbar - gammabar)` at the forward
    acceleration `zdot`) and the dependent variations eliminated by the constraints (paper eqs. 23,
    28) through the multipliers `b = cdot_zd^-T Phi_zd` and `e = c_yd^-T (Phi_yd - cdot_yd^T b)`,
    i.e. for `Lambda = Phi - b^T cdot - e^T c`, whose partial derivatives with respect to `y_d`
    and `z_d` vanish:

    - `S1^T mu + T1^T nu - R1^T = Lambda_y` (the right-hand side of the `mu` equation of eq. 43),
    - `S2^T mu + T2^T nu = Lambda_z` (that of the `nu` equation: `(Mbar nu)' = Lambda_z`),
    - `R2 - mu^T S3 - nu^T T3 = -Lambda_p` (the integrand of eq. 44, only with `design=True`).

    One `jax.vjp` of `Phi` (with respect to `(y_r, z_r)`, and `p` for the design term) and the
    cheap ones of `cdot` and `c` give all of them: no matrix `S_i`, `T_i` is formed, and the design
    term costs one reverse pass whatever the number of parameters.

    **Returns:** `(Lambda_y (f,), Lambda_z (f,), nu (f,), Lambda_p)` with `Lambda_p` a pytree like
    the float leaves of `scene` (`None` unless `design`).
    """
    model = case.model
    y_r, z_r, zdot = model.state_and_accelerations(t, y, z, scene)
    nu = spd_solve(model.minimal_terms(t, y_r, z_r, scene)[0], w)
    c, cdot, v, ode, f = _redundant_functions(case, t, zdot)
    dyn, static = eqx.partition(scene, eqx.is_inexact_array)

    def phi(y_r, z_r, dyn_):
        s = eqx.combine(dyn_, static)
        return jnp.sum(nu * ode(y_r, z_r, s)[0]) - jnp.sum(mu * v(y_r, z_r)) - f(y_r, s)

    phi_y, phi_z, lam_p = jax.grad(phi, argnums=(0, 1, 2))(y_r, z_r, dyn)

    lam_y, lam_z = model.split(phi_y)[0], model.split(phi_z)[0]
    if model.partition.dependent:
        c_i, _, lu = model._velocity_level(t, y_r, scene)  # C_i and the factors of C_d = cdot_zd = c_yd
        b = lu_solve(lu, model.split(phi_z)[1], trans=1)
        _, cdot_pull = jax.vjp(lambda a, d: cdot(a, z_r, eqx.combine(d, static)), y_r, dyn)
        cdot_y_b, cdot_p_b = cdot_pull(b)
        q_ind, q_dep = model.split(phi_y - cdot_y_b)
        e = lu_solve(lu, q_dep, trans=1)
        lam_y = q_ind - matmul(c_i.T, e)
        lam_z = lam_z - matmul(c_i.T, b)
        if design:
            _, c_pull = jax.vjp(lambda d: c(y_r, eqx.combine(d, static)), dyn)
            (c_p_e,) = c_pull(e)
            lam_p = jax.tree_util.tree_map(lambda a, g, h: a - g - h, lam_p, cdot_p_b, c_p_e)
    return lam_y, lam_z, nu, lam_p if design else None


def gauss_legendre(order: int):
    """Nodes in `[0, 1]` and weights (summing to 1) of the `order`-point Gauss–Legendre rule."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    return 0.5 * (nodes + 1.0), 0.5 * weights


def _quadrature_on_steps(case, scene, forward, backward: diffrax.DenseInterpolation, order: int, chunk: int):
    """`int_{t0}^{t1} (R2 - mu^T S3 - nu^T T3) dt` (paper eq. 44) as a flat `(n_p,)` vector.

    Gauss–Legendre with `order` nodes on every accepted backward step, `(mu, Mbar nu)` from the
    step's own dense interpolant and `(y, z)` from the forward dense output. The steps are processed
    `chunk` at a time, every node of a chunk in one `jax.vmap`; steps past the last one are padded
    (repeating the last step with weight zero).
    """
    unit_nodes, unit_weights = (jnp.asarray(a) for a in gauss_legendre(order))
    n_steps = backward.ts_size - 1
    taus, infos, direction = backward.ts, backward.infos, backward.direction

    def integrand(t, mu, w):
        y, z = forward.evaluate(t)[:2]
        lam_p = adjoint_products(case, t, y, z, scene, mu, w, design=True)[3]
        return -jax.flatten_util.ravel_pytree(lam_p)[0]

    def local(tau0, tau1, info, tau):
        return backward.interpolation_cls(t0=tau0, t1=tau1, **info).evaluate(tau)

    def chunk_sum(k):
        steps = k * chunk + jnp.arange(chunk)
        i = jnp.minimum(steps, n_steps - 1)
        tau0, tau1 = taus[i], taus[i + 1]
        info = jax.tree_util.tree_map(lambda a: a[i], infos)
        # Solver time tau = direction * t increases along the backward solve: steps have tau1 > tau0.
        width = jnp.where(steps < n_steps, tau1 - tau0, 0.0)
        tau = (tau0[:, None] + (tau1 - tau0)[:, None] * unit_nodes[None, :]).reshape(-1)
        repeat = lambda a: jnp.repeat(a, order, axis=0)
        mu, w = jax.vmap(local)(repeat(tau0), repeat(tau1), jax.tree_util.tree_map(repeat, info), tau)
        g = jax.vmap(integrand)(direction * tau, mu, w)
        weights = (width[:, None] * unit_weights[None, :]).reshape(-1)
        return jnp.sum(weights[:, None] * g, axis=0)

    def body(carry):
        k, total = carry
        return k + 1, total + chunk_sum(k)

    n_p = jax.flatten_util.ravel_pytree(eqx.filter(scene, eqx.is_inexact_array))[0].size
    _, total = jax.lax.while_loop(lambda carry: carry[0] * chunk < n_steps, body,
                                  (jnp.zeros((), n_steps.dtype), jnp.zeros(n_p)))
    return total


class Adjoint(AbstractSensitivity):
    """The adjoint variable method of the paper (Sect. 3.2), backward in diffrax.

    Forward: the minimal equations of motion with dense output. Backward, from `t1` to `t0`
    (paper eq. 43, final values `mu(t1) = 0`, `Mbar(t1) nu(t1) = 0`):

    `mu' = S1^T mu + T1^T nu - R1^T`,  `Mbar nu' = S2^T mu - Mbar' nu + T2^T nu`,

    solved for `(mu, w)` with `w = Mbar nu`, for which the second equation reads
    `w' = S2^T mu + T2^T nu` (no derivative of `Mbar` needed), and with the products formed by
    reverse mode ([`adjoint_products`][]). The gradient (paper eq. 44)
    `grad psi = G(t0) = int_{t0}^{t1} (R2 - mu^T S3 - nu^T T3) dt` lives in the parameter space `p`
    (the body data and scene parameters, a few hundred numbers), so that the cost does not grow
    with the number of design variables; one VJP of `p(x)` then gives the design gradient.

    By default the integral is not part of the backward ODE (whose error control would then be
    driven by the few hundred entries of `G`): it is evaluated after the backward solve by a
    `quadrature`-point Gauss–Legendre rule on every accepted backward step, with `(mu, w)` from
    the backward dense output and the forward state from the forward dense output, all nodes of
    `chunk` steps in one vectorised batch. With `quadrature=None`, `G` is integrated along in the
    backward ODE (`G' = -(R2 - mu^T S3 - nu^T T3)`, `G(t1) = 0`) as in the paper.

    **Fields:**
    - `rtol`, `atol`: tolerances of the backward solve (the paper's 1e-8 / 1e-10 by default).
    - `solver`: the backward solver (default: the forward solver where one is given, else
      `Dopri8()`: at the paper's tolerances it takes a quarter of the steps of `Tsit5()` on the
      reference case, and its 7th-order dense output feeds the quadrature).
    - `quadrature`: Gauss–Legendre nodes per backward step (default 3: exact for polynomials of
      degree 5 on each step), or `None`.
    - `chunk`: backward steps per vectorised quadrature batch.
    - `products`: how the right-hand side of eq. 43 is formed: `"reverse"` (default: one reverse
      pass, [`adjoint_products`][]) or `"matrices"` (the paper's matrices `R1, S1, S2, T1, T2` from
      `jax.jacfwd`, [`adjoint_terms`][], multiplied out; the same numbers, about 6x the cost per
      evaluation on the reference case). The design term is one VJP in both.
    - `max_steps`: step budget of the backward solve, whose dense output holds that many steps
      (default: the forward budget).

    !!! cite "Reference"
        Held, Knüfer, Seifried (2017). Structural sensitivity analysis of flexible multibody
        systems modeled with the floating frame of reference approach using the adjoint
        variable method. Multibody System Dynamics.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    solver: diffrax.AbstractSolver | None = None
    quadrature: int | None = 3
    chunk: int = 256
    products: str = eqx.field(static=True, default="reverse")
    max_steps: int | None = None

    def __check_init__(self):
        if self.quadrature is not None and (isinstance(self.quadrature, bool) or not isinstance(self.quadrature, int)
                                            or self.quadrature < 1):
            raise ValueError(f"Adjoint(quadrature=...) must be a positive number of Gauss–Legendre nodes "
                             f"per backward step, or None to integrate the gradient in the backward ODE; "
                             f"got {self.quadrature!r}.")
        if isinstance(self.chunk, bool) or not isinstance(self.chunk, int) or self.chunk < 1:
            raise ValueError(f"Adjoint(chunk=...) must be a positive number of backward steps, got {self.chunk!r}.")
        if self.products not in ("reverse", "matrices"):
            raise ValueError(f"Adjoint(products=...) must be 'reverse' or 'matrices', got {self.products!r}.")

    def backward_solve(self, case: FlexibleRodCase, scene: Scene, forward, *, solver=None, max_steps: int):
        """The backward solve of paper eq. 43 on the forward trajectory `forward` (dense).

        `solver` is the forward solver (used backward unless `self.solver` is set).

        **Returns:** the diffrax solution of `(mu, w)` (dense output; `quadrature` set) or of
        `(mu, w, G)` (`quadrature=None`; `G(t0)` the flat gradient).
        """
        dense = forward.solution
        in_ode = self.quadrature is None
        f = case.model.partition.n_independent

        def field(t, state, args):
            y, z = dense.evaluate(t)[:2]
            if self.products == "matrices":
                mu, w = state[0], state[1]
                terms = adjoint_terms(case, t, y, z, scene)
                nu = spd_solve(terms.mbar, w)
                lam_y = matmul(terms.s1.T, mu) + matmul(terms.t1.T, nu) - terms.r1
                lam_z = matmul(terms.s2.T, mu) + matmul(terms.t2.T, nu)
                lam_p = adjoint_products(case, t, y, z, scene, mu, w, design=True)[3] if in_ode else None
            else:
                lam_y, lam_z, _, lam_p = adjoint_products(case, t, y, z, scene, state[0], state[1], design=in_ode)
            if in_ode:
                return lam_y, lam_z, jax.flatten_util.ravel_pytree(lam_p)[0]
            return lam_y, lam_z

        state1 = (jnp.zeros(f), jnp.zeros(f))
        if in_ode:
            n_p = jax.flatten_util.ravel_pytree(eqx.filter(scene, eqx.is_inexact_array))[0].size
            state1 = (*state1, jnp.zeros(n_p))
        if self.solver is not None:
            solver = self.solver
        elif solver is None:
            solver = diffrax.Dopri8()
        jumps = tuple(j for j in case.jump_ts if case.t0 < j < case.t1)
        controller = diffrax.PIDController(rtol=self.rtol, atol=self.atol, jump_ts=jnp.asarray(jumps) if jumps else None)
        return diffrax.diffeqsolve(
            diffrax.ODETerm(field), solver, case.t1, case.t0, None, state1,
            stepsize_controller=controller, saveat=diffrax.SaveAt(t1=in_ode, dense=not in_ode),
            max_steps=max_steps, adjoint=diffrax.RecursiveCheckpointAdjoint(),
        )

    def value_and_grad_scene(self, case, scene, *, rtol, atol, solver, max_steps):
        forward = simulate(
            case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
            solver=solver, rtol=rtol, atol=atol, dense=True, max_steps=max_steps, jump_ts=case.jump_ts,
        )
        unravel = jax.flatten_util.ravel_pytree(eqx.filter(scene, eqx.is_inexact_array))[1]
        backward_steps = max_steps if self.max_steps is None else self.max_steps
        backward = self.backward_solve(case, scene, forward, solver=solver, max_steps=backward_steps)
        if self.quadrature is None:
            return forward.psi, unravel(backward.ys[2][-1])
        grad = _quadrature_on_steps(case, scene, forward.solution, backward.interpolation, self.quadrature, self.chunk)
        return forward.psi, unravel(grad)
