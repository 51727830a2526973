"""The adjoint method's building blocks (issue 4, paper eqs. 43–44) on a small slider–crank.

- `adjoint_products` (reverse mode, no matrices) equals the paper's matrices `R1, S1, S2, T1, T2`
  of `adjoint_terms` (forward mode) contracted with `(mu, nu)`;
- its design term `R2 - mu^T S3 - nu^T T3` equals the total derivative, along a random parameter
  direction, of `F + mu^T v - nu^T ODE` with the dependent coordinates following the constraints
  (Newton's implicit derivative of the model), computed independently by `jax.jvp`;
- the default gradient (reverse-mode products, the gradient integral evaluated by Gauss–Legendre
  quadrature on the backward steps) agrees with the paper's literal form (the matrices `R1, S1, S2,
  T1, T2` from `jax.jacfwd` in eq. 43, the gradient integral `G` carried in the backward ODE,
  eq. 44), and the quadrature converges with the number of nodes;
- bad options are clear errors.

The case is the family member `helpers.FAMILY`. The quadrature comparisons share one forward and
one backward solve, compiled once (only the quadrature itself is compiled per number of nodes),
and one solve in the paper's form, which covers both of its options (`quadrature=None`,
`products="matrices"`): the products equal the matrices pointwise (first test), so the two forms
integrate the same right-hand side.
"""

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_close_relative, random_design, small_case

import ffr_jax as fj
from ffr_jax._sensitivity._adjoint import _quadrature_on_steps, adjoint_products, adjoint_terms, gauss_legendre
from ffr_jax._dynamics._simulate import simulate
from ffr_jax._dynamics._small_linalg import matmul

RTOL, ATOL = 1e-10, 1e-12
BACKWARD = dict(rtol=1e-10, atol=1e-16)  # two decades tighter than the default, so that the bound below can hold
# Reverse vs forward mode of the same functions: the same numbers up to rounding (a few hundred
# operations on O(1) quantities: ~1e-14 at most; measured 2e-16…7e-16 relative to the largest entry).
PRODUCTS_RTOL = 1e-11
# The default gradient (products, 3-point Gauss–Legendre on the backward steps) vs the paper's
# form (matrices, G integrated in the backward ODE): two backward solves at rtol 1e-10 that take
# different steps (G enters the error control of the second), so they differ by the solves'
# accuracy, ~1e-10 times the growth of the error over the solve (allowed: 10); the quadrature's
# own error (degree 5 on each step of a 7th-order interpolant) is far smaller. Measured 2e-13.
QUADRATURE_VS_ODE = 1e-9


@pytest.fixture(scope="module")
def case():
    return small_case()


@pytest.fixture(scope="module")
def scene(case):
    return eqx.filter_jit(lambda x: case.scene(x))(random_design(case, 0))


@pytest.fixture(scope="module")
def states(case, solves):
    """Forward states `(t, y, z)` at a few times (from the dense output of the forward solve of
    `solves`, no solve of their own) and random adjoint variables `(mu, w)`."""
    (forward, _), _ = solves
    ts = jnp.array([0.013, 0.071, 0.138])  # one in the run-up, two at full speed
    ys, zs = eqx.filter_jit(lambda sol: jax.vmap(sol.evaluate)(ts)[:2])(forward)
    rng = np.random.default_rng(3)
    f = case.model.partition.n_independent
    return [(ts[k], ys[k], zs[k], jnp.asarray(rng.normal(size=f)), jnp.asarray(rng.normal(size=f)))
            for k in range(ts.size)]


@pytest.fixture(scope="module")
def pointwise(case, scene, states):
    """At each state: the reverse-mode products `(lam_y, lam_z, nu)` and the design term contracted
    with a random parameter direction, next to that term's independent `jax.jvp` (one compiled
    program), and the paper's matrices `R1, S1, S2, T1, T2, Mbar` by `jax.jacfwd` (a second one)."""
    model = case.model
    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(dyn)
    direction = jnp.asarray(np.random.default_rng(5).normal(size=flat.size)) * jnp.abs(flat)

    def total(t, y, z, mu, nu, zdot, p):
        """`F + mu^T v - nu^T ODE` at parameters `p`, fixed `(t, y, z, zdot)`."""
        s = eqx.combine(unravel(p), static)
        y_r, z_r = model.state(t, y, z, s)  # dependent coordinates follow the constraints
        mbar, rhs = model.minimal_terms(t, y_r, z_r, s)
        ode = matmul(mbar, zdot) - rhs
        return case.integrand(t, y_r, z_r, s) + jnp.sum(mu * model.split(z_r)[0]) - jnp.sum(nu * ode)

    @jax.jit
    def products(t, y, z, mu, w):
        lam_y, lam_z, nu, lam_p = adjoint_products(case.problem, t, y, z, (scene, case.objective), mu, w, design=True)
        zdot = model.state_and_accelerations(t, y, z, scene)[2]
        along = jax.jvp(lambda p: total(t, y, z, mu, nu, zdot, p), (flat,), (direction,))[1]
        return lam_y, lam_z, nu, -jax.flatten_util.ravel_pytree(lam_p)[0] @ direction, along

    terms = jax.jit(lambda t, y, z: adjoint_terms(case.problem, t, y, z, (scene, case.objective)))
    return [(t, mu, w, products(t, y, z, mu, w), terms(t, y, z)) for t, y, z, mu, w in states]


def test_products_equal_the_paper_matrices(pointwise):
    for t, mu, w, (lam_y, lam_z, nu, _, _), m in pointwise:
        assert_close_relative(matmul(m.mbar, nu), w, PRODUCTS_RTOL, f"Mbar nu = w at t = {t}")
        assert_close_relative(lam_y, matmul(m.s1.T, mu) + matmul(m.t1.T, nu) - m.r1, PRODUCTS_RTOL,
                              f"S1^T mu + T1^T nu - R1^T at t = {t}")
        assert_close_relative(lam_z, matmul(m.s2.T, mu) + matmul(m.t2.T, nu), PRODUCTS_RTOL,
                              f"S2^T mu + T2^T nu at t = {t}")


def test_design_term_is_the_total_parameter_derivative(pointwise):
    """`-Lambda_p . dp = d/de [F + mu^T v - nu^T ODE](p + e dp)` at fixed `(t, y, z, zdot)`."""
    for t, _, _, (_, _, _, design_term, along), _ in pointwise:
        # The same derivative by reverse mode (the products) and forward mode (jvp): equal up to
        # round-off, amplified by cancellation in the contraction with a random direction (its
        # terms reach ~1e3 times the sum); measured 3e-16 relative.
        np.testing.assert_allclose(design_term, along, rtol=PRODUCTS_RTOL,
                                   err_msg=f"(R2 - mu^T S3 - nu^T T3) . dp vs jax.jvp at t = {t}")


@pytest.fixture(scope="module")
def solves(case, scene):
    """The forward (dense) and backward solves of the default method, and the gradient of the
    paper's literal form (jacfwd matrices, `G` integrated in the backward ODE)."""
    adjoint = fj.Adjoint(**BACKWARD)

    @eqx.filter_jit
    def run(scene):
        forward = simulate(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
                           rtol=RTOL, atol=ATOL, dense=True, jump_ts=case.jump_ts, max_steps=20_000)
        backward, _ = adjoint.backward_solve(case.problem.with_scene(scene), forward, max_steps=20_000)
        return forward.solution, backward.interpolation

    paper = fj.Adjoint(**BACKWARD, quadrature=None, products="matrices")
    in_ode = eqx.filter_jit(lambda s: paper.value_and_grad_scene(case.problem, s, rtol=RTOL, atol=ATOL, solver=None,
                                                                 max_steps=20_000))
    g_paper = jax.flatten_util.ravel_pytree(eqx.filter(in_ode(scene)[1], eqx.is_inexact_array))[0]
    return run(scene), np.asarray(g_paper)


@pytest.fixture(scope="module")
def quadrature_gradients(case, scene, solves):
    (forward, backward), _ = solves
    out = {}
    for order in (1, 3):
        fn = eqx.filter_jit(lambda s, f, b, order=order: _quadrature_on_steps(
            case.problem, (s, case.objective), f, b, order, 64))
        out[order] = np.asarray(fn(scene, forward, backward))
    return out


def test_quadrature_agrees_with_the_paper_form_in_the_backward_ode(quadrature_gradients, solves):
    """Default (products, 3-point Gauss–Legendre on the backward steps) vs the paper's literal form."""
    _, g_paper = solves
    assert_close_relative(quadrature_gradients[3], g_paper, QUADRATURE_VS_ODE,
                          "3-point Gauss–Legendre gradient vs the paper's form (jacfwd matrices, G in the backward ODE)")


def test_quadrature_error_falls_with_the_number_of_nodes(quadrature_gradients, solves):
    _, g_paper = solves
    scale = np.abs(g_paper).max()
    errors = {n: np.abs(quadrature_gradients[n] - g_paper).max() / scale for n in (1, 3)}
    assert errors[3] < 1e-3 * errors[1], f"relative error vs the in-ODE gradient by number of nodes: {errors}"


def test_gauss_legendre_rule_is_exact_to_degree_2n_minus_1():
    for n in (1, 2, 3, 5):
        nodes, weights = gauss_legendre(n)
        for degree in range(2 * n):
            np.testing.assert_allclose(weights @ nodes**degree, 1.0 / (degree + 1), rtol=1e-13,
                                       err_msg=f"{n}-point rule, degree {degree}")


@pytest.mark.parametrize("bad", [dict(quadrature=0), dict(quadrature=True), dict(chunk=0), dict(products="forward")])
def test_bad_options_are_clear_errors(bad):
    with pytest.raises(ValueError, match="Adjoint"):
        fj.Adjoint(**bad)

