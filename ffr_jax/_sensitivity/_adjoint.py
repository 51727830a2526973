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

from .._checks import optional_integer, tolerances
from .._dynamics._problem import Problem
from .._dynamics._small_linalg import lu_factor, lu_solve, matmul, spd_solve
from .._solver._rosenbrock import AbstractRosenbrock
from ._base import AbstractSensitivity, forward_solve, problem_gradient
from ._forward_grid import ForwardGridSolution, backward_on_forward_grid


class AdjointTerms(eqx.Module):
    """The matrices of paper eqs. 25, 30, 33 at one time, plus what the adjoint ODE needs.

    `R1` `(f,)`, `Rz` `(f,)` (the velocity counterpart of `R1`, zero for integrands of positions
    only), `S1`, `S2`, `T1`, `T2` `(f, f)`, `Mbar`, `Mbar_dot` `(f, f)`; the design terms `R2`,
    `S3`, `T3` are never formed (see `adjoint_products`).
    """

    r1: jnp.ndarray
    rz: jnp.ndarray
    s1: jnp.ndarray
    s2: jnp.ndarray
    t1: jnp.ndarray
    t2: jnp.ndarray
    mbar: jnp.ndarray
    mbar_dot: jnp.ndarray


def _redundant_functions(problem: Problem, t, zdot):
    """The paper's functions of `(y_r, z_r, p)` at fixed `t` and `zdot`: `c`, `cdot`, `v`, `ODE`, `F`.

    The parameters `p` are the pair `(scene, objective)`: the objective's own arrays (weights,
    target paths) are parameters like the scene's.
    """
    model = problem.model

    def c(y_r, params):
        return params[0].constraint_residual(t, y_r)

    def cdot(y_r, z_r, params):
        return model.velocity_constraint(t, y_r, z_r, params[0])

    def v(y_r, z_r):
        return model.split(z_r)[0]

    def ode(y_r, z_r, params):
        mbar, rhs = model.minimal_terms(t, y_r, z_r, params[0])
        return matmul(mbar, zdot) - rhs, mbar

    def f(y_r, z_r, params):
        integrand = params[1].integrand
        if integrand is None:
            return jnp.zeros((), y_r.dtype)
        return integrand(t, y_r, z_r, params[0])

    return c, cdot, v, ode, f


def adjoint_terms(problem: Problem, t, y, z, params) -> AdjointTerms:
    """`R1, Rz, S1, S2, T1, T2, Mbar, dMbar/dt` at `(t, y, z)` as matrices (paper eqs. 25, 30, 33).

    All partial derivatives with respect to the redundant coordinates come from `jax.jacfwd`;
    the variations of the dependent coordinates are eliminated with the position and velocity
    constraints exactly as in the paper (eqs. 23, 28):
    `dy_d/dy = -c_yd^-1 c_y`, `dz_d/dy = -cdot_zd^-1 (cdot_y + cdot_yd dy_d/dy)`,
    `dz_d/dz = -cdot_zd^-1 cdot_z`. `Rz = F_z + F_zd dz_d/dz` is the velocity term of an integrand
    that depends on velocities (zero in the paper, whose integrands see positions only).

    The adjoint solve uses the products of these matrices with `(mu, nu)` instead
    (`adjoint_products`, the same numbers without forming the matrices); this form states the
    paper's terms one by one and checks the products in the tests.
    """
    model = problem.model
    ind = np.asarray(model.partition.independent, int)
    dep = np.asarray(model.partition.dependent, int)
    y_r, z_r, zdot = model.state_and_accelerations(t, y, z, params[0])
    c, cdot, v, ode, f = _redundant_functions(problem, t, zdot)

    c_y = jax.jacfwd(c)(y_r, params)
    cd_y, cd_z = jax.jacfwd(cdot, argnums=(0, 1))(y_r, z_r, params)
    v_y, v_z = jax.jacfwd(v, argnums=(0, 1))(y_r, z_r)
    o_y, o_z = jax.jacfwd(lambda a, b: ode(a, b, params)[0], argnums=(0, 1))(y_r, z_r)
    f_y, f_z = jax.grad(f, argnums=(0, 1))(y_r, z_r, params)

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
        r1 = f_y[ind] + matmul(dyd_dy.T, f_y[dep]) + matmul(dzd_dy.T, f_z[dep])
        rz = f_z[ind] + matmul(dzd_dz.T, f_z[dep])
    else:
        s1, s2 = -v_y[:, ind], -v_z[:, ind]
        t1, t2 = o_y[:, ind], o_z[:, ind]
        r1, rz = f_y[ind], f_z[ind]

    def mbar_fn(tt, yy):
        return model.minimal_terms(tt, yy, z_r, params[0])[0]

    mbar, mbar_dot = jax.jvp(mbar_fn, (t, y_r), (jnp.ones_like(t), z_r))
    return AdjointTerms(r1=r1, rz=rz, s1=s1, s2=s2, t1=t1, t2=t2, mbar=mbar, mbar_dot=mbar_dot)


def constrained_gradient(problem: Problem, t, y_r, z_r, params, phi, *, design: bool):
    """The gradient of a scalar `Phi(y_r, z_r, p)` along the constraint manifold, by reverse mode.

    With the dependent variations eliminated by the position and velocity constraints (paper eqs.
    23, 28) through the multipliers `b = cdot_zd^-T Phi_zd` and `e = c_yd^-T (Phi_yd - cdot_yd^T b)`,
    i.e. for `Lambda = Phi - b^T cdot - e^T c`, whose partial derivatives with respect to `y_d`
    and `z_d` vanish, the total derivatives of `Phi` with respect to the independent positions and
    velocities and to the parameters are `Lambda_y`, `Lambda_z` and `Lambda_p`. One `jax.grad` of
    `Phi` and the cheap VJPs of `cdot` and `c` give all three.

    **Returns:** `(Lambda_y (f,), Lambda_z (f,), Lambda_p)` with `Lambda_p` a pytree like the float
    leaves of `params` (`None` unless `design`).
    """
    model = problem.model
    c, cdot, _, _, _ = _redundant_functions(problem, t, None)
    dyn, static = eqx.partition(params, eqx.is_inexact_array)

    def phi_dyn(a, b, d):
        return phi(a, b, eqx.combine(d, static))

    if design:
        phi_y, phi_z, lam_p = jax.grad(phi_dyn, argnums=(0, 1, 2))(y_r, z_r, dyn)
    else:
        (phi_y, phi_z), lam_p = jax.grad(phi_dyn, argnums=(0, 1))(y_r, z_r, dyn), None

    lam_y, lam_z = model.split(phi_y)[0], model.split(phi_z)[0]
    if model.partition.dependent:
        c_i, _, lu = model._velocity_level(t, y_r, params[0])  # C_i and the factors of C_d = cdot_zd = c_yd
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
    return lam_y, lam_z, lam_p


def adjoint_products(problem: Problem, t, y, z, params, mu, w, *, design: bool = False):
    """The terms of paper eqs. 43–44 at `(t, y, z)` as products with the adjoint variables, by reverse mode.

    The adjoint variables are `mu` and `w = Mbar nu`; `nu = Mbar^-1 w`. With
    `Phi(y_r, z_r, p) = nu^T ODE - mu^T v - F` (`ODE = Mbar zdot - (fbar - gammabar)` at the forward
    acceleration `zdot`) and its gradient along the constraints `Lambda` ([`constrained_gradient`][]):

    - `S1^T mu + T1^T nu - R1^T = Lambda_y` (the right-hand side of the `mu` equation of eq. 43),
    - `S2^T mu + T2^T nu - Rz^T = Lambda_z` (that of the `nu` equation: `(Mbar nu)' = Lambda_z`;
      `Rz`, the derivative of `F` with respect to the independent velocities, extends the paper's
      eq. 43 to integrands of velocities),
    - `R2 - mu^T S3 - nu^T T3 = -Lambda_p` (the integrand of eq. 44, only with `design=True`).

    No matrix `S_i`, `T_i` is formed, and the design term costs one reverse pass whatever the
    number of parameters.

    **Returns:** `(Lambda_y (f,), Lambda_z (f,), nu (f,), Lambda_p)` with `Lambda_p` a pytree like
    the float leaves of `params` (`None` unless `design`).
    """
    model = problem.model
    scene = params[0]
    y_r, z_r, zdot = model.state_and_accelerations(t, y, z, scene)
    nu = spd_solve(model.minimal_terms(t, y_r, z_r, scene)[0], w)
    _, _, v, ode, f = _redundant_functions(problem, t, zdot)

    def phi(y_r, z_r, p):
        return jnp.sum(nu * ode(y_r, z_r, p)[0]) - jnp.sum(mu * v(y_r, z_r)) - f(y_r, z_r, p)

    lam_y, lam_z, lam_p = constrained_gradient(problem, t, y_r, z_r, params, phi, design=design)
    return lam_y, lam_z, nu, lam_p


# The backward solve evaluates the products at several places (diffrax's first step size, the stages, the FSAL
# evaluation): behind a jit boundary they are traced once per structure and shapes, not at each (XLA inlines the
# calls again: the same program). The README mechanism's first gradient: tracing 10.1 -> 6.2 s (benchmarks/RESULTS.md,
# "Where a first call's time goes").
_adjoint_products_once = eqx.filter_jit(adjoint_products)


def terminal_products(problem: Problem, t, y, z, params):
    """End conditions of the adjoint ODE and the terminal term's share of the gradient.

    For `psi = G(t1, y_r, z_r, p) + int F dt`, the boundary terms of paper eq. 42 at `t1` become
    `(dG/dy - mu^T) dy(t1) + (dG/dz - nu^T Mbar) dz(t1)`, so the adjoint variables end at
    `mu(t1) = dG/dy^T` and `w(t1) = Mbar nu(t1) = dG/dz^T` (both zero without a terminal term, as
    in eq. 43), and the gradient gains `dG/dp`; all three are total derivatives along the
    constraints (the dependent coordinates eliminated as in eqs. 23, 28: [`constrained_gradient`][]
    with `Phi = G`).

    **Returns:** `(mu(t1) (f,), w(t1) (f,), dG/dp)`.
    """
    y_r, z_r = problem.model.state(t, y, z, params[0])

    def phi(y_r, z_r, p):
        return p[1].terminal(t, y_r, z_r, p[0])

    return constrained_gradient(problem, t, y_r, z_r, params, phi, design=True)


QUADRATURE_BATCH = 2**17
"""Default size of one vectorised quadrature batch, in nodes times parameters (see `quadrature_chunk`)."""


def quadrature_chunk(order: int, n_params: int, chunk: int | None = None) -> int:
    """Backward steps per vectorised quadrature batch: `chunk` when given, else
    `clip(QUADRATURE_BATCH // (order n_params), 1, 256)`.

    A batch evaluates the reverse pass of eq. 44's integrand at `chunk * order` nodes at once, and
    its intermediates grow with the number of parameters `n_params` (about `3 n_modes^2` body-data
    entries per flexible body). A fixed 256 steps (768 nodes) fits at 6 modes (181 parameters on
    the slider-crank) but made the quadrature, not the backward solve, the cost at 20-40 modes
    (1,385-5,145 parameters: minutes and 3-10 GB, where 16 steps took 24 s; issue 15). The
    default keeps `chunk * order * n_params` near `2^17` (about 1 MB of gradient rows per batch,
    and the intermediates a few hundred times that): 241 steps at 6 modes, 31 at 20, 8 at 40.
    """
    if chunk is not None:
        return chunk
    return int(min(256, max(1, QUADRATURE_BATCH // (order * max(n_params, 1)))))


def gauss_legendre(order: int):
    """Nodes in `[0, 1]` and weights (summing to 1) of the `order`-point Gauss–Legendre rule."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    return 0.5 * (nodes + 1.0), 0.5 * weights


def _quadrature_on_steps(problem, params, forward, backward: diffrax.DenseInterpolation | ForwardGridSolution, order: int,
                         chunk: int | None):
    """`int_{t0}^{t1} (R2 - mu^T S3 - nu^T T3) dt` (paper eq. 44) as a flat `(n_p,)` vector.

    Gauss–Legendre with `order` nodes on every accepted backward step, `(mu, Mbar nu)` from the
    step's own dense interpolant and `(y, z)` from the forward dense output. The steps are processed
    `chunk` at a time, every node of a chunk in one `jax.vmap`; steps past the last one are padded
    (repeating the last step with weight zero). `chunk=None`: sized by `quadrature_chunk`.
    """
    n_p = jax.flatten_util.ravel_pytree(eqx.filter(params, eqx.is_inexact_array))[0].size
    chunk = quadrature_chunk(order, n_p, chunk)
    unit_nodes, unit_weights = (jnp.asarray(a) for a in gauss_legendre(order))
    # A failed solve's step count is the largest integer in equinox's `nan` error mode (the cacheable programs):
    # the loop is bounded by the buffer, never by that count (issue 32: an endless loop after the step budget).
    n_steps = jnp.minimum(backward.ts_size - 1, backward.ts.shape[0] - 1)
    taus, infos, direction = backward.ts, backward.infos, backward.direction

    def integrand(t, mu, w):
        y, z = forward.evaluate(t)[:2]
        lam_p = adjoint_products(problem, t, y, z, params, mu, w, design=True)[3]
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
        mu, w = jax.vmap(local)(repeat(tau0), repeat(tau1), jax.tree_util.tree_map(repeat, info), tau)[:2]
        g = jax.vmap(integrand)(direction * tau, mu, w)
        weights = (width[:, None] * unit_weights[None, :]).reshape(-1)
        return jnp.sum(weights[:, None] * g, axis=0)

    def body(carry):
        k, total = carry
        return k + 1, total + chunk_sum(k)

    _, total = jax.lax.while_loop(lambda carry: carry[0] * chunk < n_steps, body,
                                  (jnp.zeros((), n_steps.dtype), jnp.zeros(n_p)))
    return total


class Adjoint(AbstractSensitivity):
    """The adjoint variable method of the paper (Sect. 3.2), backward in diffrax.

    Forward: the minimal equations of motion with dense output. Backward, from `t1` to `t0`
    (paper eq. 43, extended to objectives of velocities and to a terminal term):

    `mu' = S1^T mu + T1^T nu - R1^T`,  `Mbar nu' = S2^T mu - Mbar' nu + T2^T nu - Rz^T`,

    solved for `(mu, w)` with `w = Mbar nu`, for which the second equation reads
    `w' = S2^T mu + T2^T nu - Rz^T` (no derivative of `Mbar` needed), and with the products formed
    by reverse mode (`adjoint_products`). `Rz` is the derivative of the integrand `F` with
    respect to the independent velocities (zero for the paper's integrands of positions). The
    end values are `mu(t1) = dG/dy`, `w(t1) = dG/dz` for a terminal term `G(t1, y_r, z_r, p)`
    (zero without one, as in eq. 43; `terminal_products`).

    The gradient (paper eq. 44 plus the terminal term)
    `grad psi = int_{t0}^{t1} (R2 - mu^T S3 - nu^T T3) dt + dG/dp` lives in the parameter space
    `p` (the body data and scene parameters, a few hundred numbers), so that the cost does not
    grow with the number of design variables; one VJP of `p(x)` then gives the design gradient.
    The initial state is a parameter too: integrating the terms `mu^T dy` and `nu^T Mbar dz` of
    eqs. 36 and 40 by parts leaves `dpsi/dy0 = mu(t0)` and `dpsi/dz0 = w(t0)`.

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
      reference case, and its 7th-order dense output feeds the quadrature). With a Rosenbrock
      method (`ffr_jax.Rodas5P()`, the stiff route) the backward ODE, linear in `(mu, w)`, has its
      stages solved exactly with the Jacobian `-J^T` of the equations of motion (see `grid`).
    - `grid`: where the backward solve steps. `None` (default): on the forward's accepted steps
      when the backward solver is a Rosenbrock method and `quadrature` is set
      (`ffr_jax/_sensitivity/_forward_grid.py`: no step control, no rejected steps, the Jacobian
      by forward mode through the equations of motion; on the reference case at 6 modes and
      rtol 1e-8 0.96 s backward against a 0.29 s forward, benchmarks/profile_adjoint_split.py), else diffrax's adaptive solve; `"forward"` insists on
      the former, `"adaptive"` on the latter (which also resolves the fast modes' free oscillations
      of the adjoint, several times the cost). On the forward grid the gradient's error is about 100
      rtol; [`DiscreteAdjoint`][ffr_jax.DiscreteAdjoint], the transpose of the Rosenbrock steps
      themselves, is the derivative of the computed psi and the cheaper gradient at equal accuracy
      (benchmarks/RESULTS.md, "The discrete adjoint of Rodas5P").
    - `quadrature`: Gauss–Legendre nodes per backward step (default 3: exact for polynomials of
      degree 5 on each step), or `None`.
    - `chunk`: backward steps per vectorised quadrature batch (default `None`: sized by the
      number of parameters so that a batch stays near `2^17` node-parameter entries,
      `quadrature_chunk`; 241 steps at 6 modes, 8 at 40).
    - `products`: how the right-hand side of eq. 43 is formed: `"reverse"` (default: one reverse
      pass, `adjoint_products`) or `"matrices"` (the paper's matrices `R1, Rz, S1, S2, T1, T2`
      from `jax.jacfwd`, `adjoint_terms`, multiplied out; the same numbers, about 6x the cost
      per evaluation on the reference case). The design term is one VJP in both.
    - `max_steps`: step budget of the backward solve, whose dense output holds that many steps
      (default: the forward budget; on the forward grid the backward solve takes the forward's steps).

    !!! cite "Reference"
        Held, Knüfer, Seifried (2017). Structural sensitivity analysis of flexible multibody
        systems modeled with the floating frame of reference approach using the adjoint
        variable method. Multibody System Dynamics.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    solver: diffrax.AbstractSolver | None = None
    quadrature: int | None = 3
    chunk: int | None = None
    products: str = eqx.field(static=True, default="reverse")
    max_steps: int | None = None
    grid: str | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        tolerances(self.rtol, self.atol, "Adjoint (the backward solve)")
        optional_integer(self.max_steps, "Adjoint(max_steps=...)")
        if self.quadrature is not None and (isinstance(self.quadrature, bool) or not isinstance(self.quadrature, int)
                                            or self.quadrature < 1):
            raise ValueError(f"Adjoint(quadrature=...) must be a positive number of Gauss–Legendre nodes "
                             f"per backward step, or None to integrate the gradient in the backward ODE; "
                             f"got {self.quadrature!r}.")
        if self.chunk is not None and (isinstance(self.chunk, bool) or not isinstance(self.chunk, int)
                                       or self.chunk < 1):
            raise ValueError(f"Adjoint(chunk=...) must be a positive number of backward steps (or None: sized "
                             f"by the number of parameters), got {self.chunk!r}.")
        if self.grid not in (None, "forward", "adaptive"):
            raise ValueError(f"Adjoint(grid=...) must be None, 'forward' or 'adaptive', got {self.grid!r}.")
        if self.products not in ("reverse", "matrices"):
            raise ValueError(f"Adjoint(products=...) must be 'reverse' or 'matrices', got {self.products!r}.")

    def backward_solver(self, forward_solver=None) -> diffrax.AbstractSolver:
        """The solver of the backward solve: `solver`, else the forward one, else `Dopri8()`."""
        if self.solver is not None:
            return self.solver
        return diffrax.Dopri8() if forward_solver is None else forward_solver

    def on_forward_grid(self, backward_solver) -> bool:
        """Whether the backward solve steps on the forward's accepted steps (see `grid`)."""
        if self.grid == "adaptive":
            return False
        rosenbrock = isinstance(backward_solver, AbstractRosenbrock)
        if self.grid == "forward" and not (rosenbrock and self.quadrature is not None):
            raise ValueError(
                "Adjoint(grid='forward') needs a Rosenbrock backward solver (e.g. ffr_jax.Rodas5P(); got "
                f"{type(backward_solver).__name__}) and quadrature set (got {self.quadrature!r}): the backward "
                "stages are solved with the exact Jacobian -J^T of the equations of motion, and the gradient "
                "integral is not part of the backward ODE. Use grid='adaptive' for other solvers.")
        return rosenbrock and self.quadrature is not None

    def backward_solve(self, problem: Problem, forward, *, solver=None, max_steps: int):
        """The backward solve of paper eq. 43 on the forward trajectory `forward` (dense).

        `solver` is the forward solver (used backward unless `self.solver` is set).

        **Returns:** `(solution, dG/dp)`: the diffrax solution of `(mu, w)` (dense output and the
        value at `t0`; `quadrature` set) or of `(mu, w, G)` (`quadrature=None`; `G(t0)` the flat
        gradient), and the terminal term's share of the gradient (`None` without a terminal term).
        """
        dense = forward.solution
        in_ode = self.quadrature is None
        params = (problem.scene, problem.objective)
        f = problem.model.partition.n_independent

        def products(t, y, z, mu, w):
            if self.products == "matrices":
                terms = adjoint_terms(problem, t, y, z, params)
                nu = spd_solve(terms.mbar, w)
                lam_y = matmul(terms.s1.T, mu) + matmul(terms.t1.T, nu) - terms.r1
                lam_z = matmul(terms.s2.T, mu) + matmul(terms.t2.T, nu) - terms.rz
                lam_p = adjoint_products(problem, t, y, z, params, mu, w, design=True)[3] if in_ode else None
            else:
                lam_y, lam_z, _, lam_p = _adjoint_products_once(problem, t, y, z, params, mu, w, design=in_ode)
            if in_ode:
                return lam_y, lam_z, jax.flatten_util.ravel_pytree(lam_p)[0]
            return lam_y, lam_z

        def field(t, state, args):
            y, z = dense.evaluate(t)[:2]
            return products(t, y, z, *state[:2])

        t1 = jnp.asarray(problem.t1, forward.ys.dtype)
        if problem.objective.terminal is None:
            state1, terminal = (jnp.zeros(f), jnp.zeros(f)), None
        else:
            mu1, w1, terminal = terminal_products(problem, t1, forward.ys[-1], forward.zs[-1], params)
            state1 = (mu1, w1)
        if in_ode:
            n_p = jax.flatten_util.ravel_pytree(eqx.filter(params, eqx.is_inexact_array))[0].size
            state1 = (*state1, jnp.zeros(n_p))
        solver = self.backward_solver(solver)
        if self.on_forward_grid(solver):
            def accelerations(t, y, z):
                return problem.model.state_and_accelerations(t, y, z, problem.scene)[2]

            solution = backward_on_forward_grid(solver, dense.interpolation, products, accelerations, state1,
                                                rtol=self.rtol, atol=self.atol)
            return solution, terminal
        jumps = problem.jump_ts
        controller = diffrax.PIDController(rtol=self.rtol, atol=self.atol, jump_ts=jnp.asarray(jumps) if jumps else None)
        # Where the forward solve failed (its values NaN: equinox's `nan` error mode of the cacheable programs), the
        # backward solve spans no time instead of spending its step budget on NaN; the caller reports the failure.
        t_end = jnp.where(jnp.isfinite(forward.psi), problem.t0, problem.t1)
        solution = diffrax.diffeqsolve(
            diffrax.ODETerm(field), solver, problem.t1, t_end, None if problem.dt0 is None else -problem.dt0, state1,
            stepsize_controller=controller, saveat=diffrax.SaveAt(t1=True, dense=not in_ode),
            max_steps=max_steps, adjoint=diffrax.RecursiveCheckpointAdjoint(),
        )
        return solution, terminal

    def value_and_grad_problem(self, problem, *, rtol, atol, solver, max_steps):
        forward = forward_solve(problem, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps, dense=True)
        params = (problem.scene, problem.objective)
        unravel = jax.flatten_util.ravel_pytree(eqx.filter(params, eqx.is_inexact_array))[1]
        backward_steps = max_steps if self.max_steps is None else self.max_steps
        backward, terminal = self.backward_solve(problem, forward, solver=solver, max_steps=backward_steps)
        if self.quadrature is None:
            grad = backward.ys[2][-1]
        else:
            grad = _quadrature_on_steps(problem, params, forward.solution, backward.interpolation, self.quadrature,
                                        self.chunk)
        if terminal is not None:
            grad = grad + jax.flatten_util.ravel_pytree(terminal)[0]
        g_scene, g_objective = unravel(grad)
        mu0, w0 = backward.ys[0][-1], backward.ys[1][-1]
        return forward.psi, problem_gradient(problem, (g_scene, g_objective, mu0, w0))
