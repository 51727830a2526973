"""The stiff route (Rosenbrock Rodas5P forward, and backward where a method solves backward) gives the
psi and design gradient of the explicit route (Dopri8) for every gradient method, and the gradient
guard (`check_gradient`, `value_and_grad(..., check=True)`) tells a wrong gradient from a right one
(issue 15).

The family member of `helpers.small_case()` (12 x 2 mesh, 4 modes, t1 = 0.15 s with a 0.05 s crank run-up) and one
random design; the explicit reference is autodiff through Dopri8 at the paper's tolerances, the very program
tests/test_sensitivity.py compiles for the family (a plain `fj.value_and_grad` call, compiled once per process and
structure): this module runs in the family's pytest-xdist group (tests/suite_plan.py), so the reference costs no
compile of its own (it cost 47 s of the default suite's worker time when this module built its own case).
"""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._sensitivity._adjoint import quadrature_chunk

from helpers import assert_close_relative, random_design, small_case


RTOL, ATOL = 1e-10, 1e-12  # forward tolerances, both routes (the paper's)
# Backward tolerances as in tests/test_sensitivity.py: the adjoint states are of the size of psi
# (~1e-7 here), so the absolute tolerance sits well below it.
BACKWARD = dict(rtol=1e-10, atol=1e-16)

# psi: both solves carry the global error of an adaptive solve at rtol 1e-10, measured 1.1e-10
# relative for Rodas5P on this case against Dopri8 at rtol 1e-12 (tests/test_solvers.py);
# 1e-8 allows two orders above it.
PSI_AGREE = 1e-8
# Gradients: relative to the largest entry. The explicit reference is autodiff through Dopri8; the
# same method on the two routes differs by the two discretisations' errors in the derivative
# (each of the order of the tolerances, ~1e-9..1e-8 after the design map's VJP), and methods differ
# from each other by 1e-6 at most at these tolerances (tests/test_sensitivity.py: adjoint vs
# autodiff 1e-6, backsolve 1e-5). The stiff route must meet the same bounds.
# The discrete adjoint (tests/test_discrete_adjoint.py) is the derivative of the discrete psi, as
# autodiff is: the same bound.
GRADIENT_AGREE = {"adjoint": 1e-6, "autodiff": 1e-6, "backsolve": 1e-5, "discrete-adjoint": 1e-6}


@pytest.fixture(scope="module")
def case():
    return small_case()


@pytest.fixture(scope="module")
def x(case):
    return random_design(case, 3)


@pytest.fixture(scope="module")
def explicit(case, x):
    """`(psi, grad)` by autodiff through Dopri8 (the explicit route): the family's autodiff program, shared with
    tests/test_sensitivity.py (same call, same tolerances)."""
    psi, grad = fj.value_and_grad(case, x, "autodiff", rtol=RTOL, atol=ATOL)
    return float(psi), np.asarray(grad)


def _method(name):
    return {"adjoint": fj.Adjoint(**BACKWARD), "autodiff": fj.Autodiff(), "backsolve": fj.Backsolve(**BACKWARD),
            "discrete-adjoint": fj.DiscreteAdjoint()}[name]


# Autodiff and backsolve through Rodas5P compile reverse mode through the solver's linearisation
# (about 4-5 minutes each on the loaded 2-core machine): marked slow to keep the default suite
# within its budget. The adjoint (backward on the forward's steps) compiles in 30-45 s and runs by default.
# The discrete adjoint of Rodas5P (about 40 s) is slow too: the default suite checks it step by step and
# on an objective with a terminal term (tests/test_discrete_adjoint.py).
@pytest.mark.parametrize("name", ["adjoint", pytest.param("discrete-adjoint", marks=pytest.mark.slow),
                                  pytest.param("autodiff", marks=pytest.mark.slow),
                                  pytest.param("backsolve", marks=pytest.mark.slow)])
def test_stiff_route_gives_the_explicit_psi_and_gradient(case, x, explicit, name):
    psi, grad = fj.value_and_grad(case, x, _method(name), rtol=RTOL, atol=ATOL, solver=fj.Rodas5P())
    psi_ref, grad_ref = explicit
    assert abs(float(psi) - psi_ref) <= PSI_AGREE * abs(psi_ref), f"{name}: psi {float(psi)} vs {psi_ref}"
    assert_close_relative(grad, grad_ref, GRADIENT_AGREE[name], f"{name} with Rodas5P vs autodiff with Dopri8")


def test_backward_jacobian_is_minus_the_transposed_jacobian_of_the_equations_of_motion(case, x):
    # The identity the backward solve on the forward grid rests on (ffr_jax/_sensitivity/_forward_grid.py):
    # the Jacobian of the adjoint right-hand side (paper eq. 43, in (mu, w = Mbar nu)) with respect to
    # (mu, w) is -J^T, J = d(y', z')/d(y, z) of the minimal equations of motion. Both sides are exact
    # derivatives by automatic differentiation taken in different orders (reverse pass of the products,
    # forward mode through the accelerations); they differ by rounding only, measured 1.3e-16 of the
    # largest entry on this case. Rounding in the Mbar and C_d solves grows with their condition
    # numbers along other motions and platforms, so 1e-10 leaves six orders of margin; a sign or
    # transpose error, or a missing dependent-coordinate term, is O(1).
    import jax

    from ffr_jax._sensitivity._adjoint import adjoint_products

    problem = case.problem_for(case.check(x))
    params = (problem.scene, problem.objective)
    model, f = problem.model, problem.model.partition.n_independent
    traj = fj.simulate(problem, rtol=1e-8, atol=1e-10, ts=jnp.array([0.13]))
    t, y, z = jnp.asarray(0.13), traj.ys[0], traj.zs[0]

    def rhs(lam):
        return jnp.concatenate(adjoint_products(problem, t, y, z, params, lam[:f], lam[f:], design=False)[:2])

    # Compiled: run op by op, the two Jacobians took 20 s of the default suite.
    backward = jax.jit(jax.jacfwd(rhs))(jnp.zeros(2 * f))
    a_y, a_z = jax.jit(jax.jacfwd(lambda y, z: model.state_and_accelerations(t, y, z, problem.scene)[2],
                                  argnums=(0, 1)))(y, z)
    forward = jnp.block([[jnp.zeros((f, f)), jnp.eye(f)], [a_y, a_z]])
    assert_close_relative(backward, -forward.T, 1e-10, "Jacobian of the adjoint right-hand side vs -J^T")


def test_grid_options_are_checked():
    with pytest.raises(ValueError, match="grid"):
        fj.Adjoint(grid="fixed")
    with pytest.raises(ValueError, match="Rosenbrock backward solver"):
        fj.Adjoint(grid="forward").on_forward_grid(diffrax.Dopri8())
    with pytest.raises(ValueError, match="quadrature"):
        fj.Adjoint(grid="forward", quadrature=None).on_forward_grid(fj.Rodas5P())
    assert fj.Adjoint().on_forward_grid(fj.Rodas5P())
    assert not fj.Adjoint(grid="adaptive").on_forward_grid(fj.Rodas5P())
    assert not fj.Adjoint(quadrature=None).on_forward_grid(fj.Rodas5P())


def test_gradient_check_accepts_the_gradient_and_rejects_wrong_ones(case, x, explicit):
    _, grad = explicit
    good = fj.check_gradient(case, x, grad)
    assert good.trusted, good.message()
    # A right gradient agrees with the central difference to the difference's own accuracy
    # (truncation h^2 psi''' / 6 and noise rtol psi / h with h = 1e-4: both ~1e-6 relative on this
    # case, as the central differences of tests/test_sensitivity.py); 100x below the tolerance.
    assert good.error[0] < 1e-5, good.message()
    # Wrong gradients of the kinds the guard exists for: wrong signs on part of the entries (as
    # autodiff at the stability limit returned, issue 15) and a wrong scale.
    flipped = np.where(np.arange(grad.size) % 2 == 0, -grad, grad)
    for wrong in (flipped, 1.5 * grad):
        check = fj.check_gradient(case, x, jnp.asarray(wrong))
        assert not check.trusted, check.message()
        assert "Untrustworthy gradient" in check.message()


def test_value_and_grad_check_raises_on_a_wrong_gradient(case, x, explicit, monkeypatch):
    # The right gradient passes (the autodiff program of the `explicit` fixture, reused).
    psi, grad = fj.value_and_grad(case, x, "autodiff", rtol=RTOL, atol=ATOL, check=True)
    np.testing.assert_array_equal(np.asarray(grad), explicit[1])
    # A method returning a wrong gradient (here: the compiled program's result with its sign
    # flipped, standing in for a method that differentiated the discrete solution wrongly) raises.
    import ffr_jax._api as api

    compiled = api._value_and_grad_design
    monkeypatch.setattr(api, "_value_and_grad_design", lambda *a, **kw: (lambda p, g: (p, -g))(*compiled(*a, **kw)))
    with pytest.raises(ValueError, match="Untrustworthy gradient"):
        fj.value_and_grad(case, x, "autodiff", rtol=RTOL, atol=ATOL, check=True)


def test_quadrature_chunk_is_bounded_by_the_number_of_parameters():
    # 181, 1,385 and 5,145 parameters: the slider-crank at 6, 20 and 40 modes.
    assert quadrature_chunk(3, 181) == 241
    assert quadrature_chunk(3, 1385) == 31
    assert quadrature_chunk(3, 5145) == 8
    assert quadrature_chunk(3, 10) == 256 and quadrature_chunk(3, 10**7) == 1
    assert quadrature_chunk(3, 5145, chunk=64) == 64
