"""The adjoint method's building blocks (issue 4, paper eqs. 43–44) on a small slider–crank.

- `adjoint_products` (reverse mode, no matrices) equals the paper's matrices `R1, S1, S2, T1, T2`
  of `adjoint_terms` (forward mode) contracted with `(mu, nu)`;
- its design term `R2 - mu^T S3 - nu^T T3` equals the total derivative, along a random parameter
  direction, of `F + mu^T v - nu^T ODE` with the dependent coordinates following the constraints
  (Newton's implicit derivative of the model), computed independently by `jax.jvp`;
- the gradient integral evaluated by Gauss–Legendre quadrature on the backward steps agrees with
  the integral carried in the backward ODE, and converges with the number of nodes;
- bad options are clear errors.

The gradient comparisons share one forward and one backward solve, compiled once; only the
quadrature itself is compiled per number of nodes.
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
from ffr_jax._simulate import simulate
from ffr_jax._small_linalg import matmul

NX, NY, MODES, T1 = 12, 2, 3, 0.2  # the case of tests/test_sensitivity.py
RTOL, ATOL = 1e-10, 1e-12
BACKWARD = dict(rtol=1e-10, atol=1e-16)  # states of the size of psi (~1e-7): atol well below
PRODUCTS_RTOL = 1e-11  # reverse vs forward mode: the same numbers up to rounding
QUADRATURE_VS_ODE = 1e-8  # default rule vs the integral carried in the backward ODE (relative, max norm)


@pytest.fixture(scope="module")
def case():
    return small_case(NX, NY, MODES, T1)


@pytest.fixture(scope="module")
def scene(case):
    return case.scene(random_design(case, 0))


@pytest.fixture(scope="module")
def states(case, scene):
    """Forward states `(t, y, z)` at a few times and random adjoint variables `(mu, w)`."""
    ts = jnp.array([0.013, 0.071, 0.152])
    traj = simulate(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, rtol=RTOL, atol=ATOL,
                    ts=ts, jump_ts=case.jump_ts)
    rng = np.random.default_rng(3)
    f = case.model.partition.n_independent
    return [(ts[k], traj.ys[k], traj.zs[k], jnp.asarray(rng.normal(size=f)), jnp.asarray(rng.normal(size=f)))
            for k in range(ts.size)]


def test_products_equal_the_paper_matrices(case, scene, states):
    params = (scene, case.objective)
    products = jax.jit(lambda t, y, z, mu, w: adjoint_products(case.problem, t, y, z, params, mu, w)[:3])
    terms = jax.jit(lambda t, y, z: adjoint_terms(case.problem, t, y, z, params))
    for t, y, z, mu, w in states:
        lam_y, lam_z, nu = products(t, y, z, mu, w)
        m = terms(t, y, z)
        assert_close_relative(matmul(m.mbar, nu), w, PRODUCTS_RTOL, f"Mbar nu = w at t = {t}")
        assert_close_relative(lam_y, matmul(m.s1.T, mu) + matmul(m.t1.T, nu) - m.r1, PRODUCTS_RTOL,
                              f"S1^T mu + T1^T nu - R1^T at t = {t}")
        assert_close_relative(lam_z, matmul(m.s2.T, mu) + matmul(m.t2.T, nu), PRODUCTS_RTOL,
                              f"S2^T mu + T2^T nu at t = {t}")


def test_design_term_is_the_total_parameter_derivative(case, scene, states):
    """`-Lambda_p . dp = d/de [F + mu^T v - nu^T ODE](p + e dp)` at fixed `(t, y, z, zdot)`."""
    model = case.model
    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(dyn)
    direction = jnp.asarray(np.random.default_rng(5).normal(size=flat.size)) * jnp.abs(flat)

    def total(t, y, z, mu, nu, zdot, p):
        s = eqx.combine(unravel(p), static)
        y_r, z_r = model.state(t, y, z, s)  # dependent coordinates follow the constraints
        mbar, rhs = model.minimal_terms(t, y_r, z_r, s)
        ode = matmul(mbar, zdot) - rhs
        return case.integrand(t, y_r, z_r, s) + jnp.sum(mu * model.split(z_r)[0]) - jnp.sum(nu * ode)

    @jax.jit
    def both(t, y, z, mu, w):
        _, _, nu, lam_p = adjoint_products(case.problem, t, y, z, (scene, case.objective), mu, w, design=True)
        zdot = model.state_and_accelerations(t, y, z, scene)[2]
        along = jax.jvp(lambda p: total(t, y, z, mu, nu, zdot, p), (flat,), (direction,))[1]
        return -jax.flatten_util.ravel_pytree(lam_p)[0] @ direction, along

    for t, y, z, mu, w in states:
        design_term, along = both(t, y, z, mu, w)
        np.testing.assert_allclose(design_term, along, rtol=1e-9,
                                   err_msg=f"(R2 - mu^T S3 - nu^T T3) . dp vs jax.jvp at t = {t}")


@pytest.fixture(scope="module")
def solves(case, scene):
    """The forward (dense) and backward solves of the default method, and the in-ODE gradient."""
    adjoint = fj.Adjoint(**BACKWARD)

    @eqx.filter_jit
    def run(scene):
        forward = simulate(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
                           rtol=RTOL, atol=ATOL, dense=True, jump_ts=case.jump_ts, max_steps=20_000)
        backward, _ = adjoint.backward_solve(case.problem.with_scene(scene), forward, max_steps=20_000)
        return forward.solution, backward.interpolation

    in_ode = eqx.filter_jit(lambda s: fj.Adjoint(**BACKWARD, quadrature=None).value_and_grad_scene(
        case.problem, s, rtol=RTOL, atol=ATOL, solver=None, max_steps=20_000))
    g_ode = jax.flatten_util.ravel_pytree(eqx.filter(in_ode(scene)[1], eqx.is_inexact_array))[0]
    return run(scene), np.asarray(g_ode)


@pytest.fixture(scope="module")
def quadrature_gradients(case, scene, solves):
    (forward, backward), _ = solves
    out = {}
    for order in (1, 3):
        fn = eqx.filter_jit(lambda s, f, b, order=order: _quadrature_on_steps(
            case.problem, (s, case.objective), f, b, order, 64))
        out[order] = np.asarray(fn(scene, forward, backward))
    return out


def test_quadrature_agrees_with_the_integral_in_the_backward_ode(quadrature_gradients, solves):
    _, g_ode = solves
    assert_close_relative(quadrature_gradients[3], g_ode, QUADRATURE_VS_ODE,
                          "3-point Gauss–Legendre gradient vs the gradient integrated in the backward ODE")


def test_quadrature_error_falls_with_the_number_of_nodes(quadrature_gradients, solves):
    _, g_ode = solves
    scale = np.abs(g_ode).max()
    errors = {n: np.abs(quadrature_gradients[n] - g_ode).max() / scale for n in (1, 3)}
    assert errors[3] < 1e-3 * errors[1], f"relative error vs the in-ODE gradient by number of nodes: {errors}"


def test_paper_matrices_in_the_backward_ode_give_the_same_gradient(case, scene, solves):
    """The paper's literal form — `R1, S1, S2, T1, T2` from `jax.jacfwd` in eq. 43 and `G` integrated
    in the backward ODE (eq. 44) — against the default reverse-mode products, both in the ODE."""
    _, g_ode = solves
    paper = fj.Adjoint(**BACKWARD, quadrature=None, products="matrices")
    run = eqx.filter_jit(lambda s: paper.value_and_grad_scene(case.problem, s, rtol=RTOL, atol=ATOL, solver=None,
                                                              max_steps=20_000))
    g = jax.flatten_util.ravel_pytree(eqx.filter(run(scene)[1], eqx.is_inexact_array))[0]
    assert_close_relative(np.asarray(g), g_ode, 1e-9, "gradient with the paper's jacfwd matrices vs reverse-mode products")


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

