"""The discrete adjoint of Rodas5P (`ffr_jax.DiscreteAdjoint`, issue 15) is the derivative of the computed psi.

Independent routes to the same numbers: the hand-written transpose of one Rosenbrock step against forward
mode through that step (default suite), the whole backward recursion against forward-mode differentiation
through diffrax on the forward solve's accepted steps (`diffrax.StepTo`), and an objective with a terminal term against
the paper's adjoint (both `-m slow`, for the suite's 8-minute budget; its agreement with the explicit
route is `tests/test_stiff_route.py[discrete-adjoint]`, slow too). One small slider-crank (10 x 2 mesh,
3 modes, t1 = 0.2 s, the drivers' ramp ending at t = 0.05 s inside the motion).
"""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._dynamics._simulate import solve_minimal
from ffr_jax._dynamics._small_linalg import lu_factor
from ffr_jax._solver._rosenbrock import rosenbrock_matrix, rosenbrock_stages
from ffr_jax._sensitivity._discrete_adjoint import _vector_field, step_transpose

from helpers import assert_close_relative, random_design, small_case

RTOL, ATOL = 1e-8, 1e-10


@pytest.fixture(scope="module")
def problem():
    case = small_case(10, 2, 3, 0.2)
    return case.problem_for(random_design(case, 3))


def _flat(problem, h):
    """`g(t, u, p) = h f(t, u, p)` on the flat state `(y, z, psi)` and the flat float parameters."""
    field = _vector_field(problem)
    dynamic, static = eqx.partition((problem.scene, problem.objective), eqx.is_inexact_array)
    p, unravel_p = jax.flatten_util.ravel_pytree(dynamic)
    u, unravel_u = jax.flatten_util.ravel_pytree((problem.y0, problem.z0, jnp.zeros(())))

    def g(t, u, q):
        return h * jax.flatten_util.ravel_pytree(field(t, unravel_u(u), eqx.combine(unravel_p(q), static)))[0]

    return g, u, p


def test_step_transpose_is_the_transpose_of_the_step(problem):
    # One Rodas5P step as the solver takes it (Jacobian by forward mode, LU not differentiated, the
    # stages' solves differentiated through their right-hand sides and matrix), differentiated in
    # forward mode along a random direction `(du, dp)`, against the hand-written transpose applied to
    # a random cotangent: `<u1bar, d step (du, dp)> = <step^T u1bar, (du, dp)>`. Both sides are exact
    # derivatives; they differ by rounding in the stage solves and the products, measured 1.5e-13
    # relative (the transpose agrees entry by entry with `jax.vjp` of the step to 2e-14). 1e-10
    # leaves three orders for other platforms; a missing term is O(1) here (measured: without the
    # step start's terms 4.9, without the stage VJPs 26, relative to the same scale).
    tab = fj.Rodas5P.tableau
    t0, h = 0.03, 2e-3  # inside the ramp: f_t does not vanish
    g, u0, p = _flat(problem, h)
    u0 = u0 + jnp.concatenate([jnp.full(3, 0.01), jnp.full(3, 0.3), jnp.zeros(1)])

    def step(u, q):
        def g_of(t, uu):
            return g(t, uu, q)

        g0, g_t, matrix = rosenbrock_matrix(tab, g_of, t0, u)
        ks = rosenbrock_stages(tab, g_of, t0, h, u, g0, g_t, matrix, lu_factor(jax.lax.stop_gradient(matrix)))
        return u + jnp.asarray(tab.b) @ ks

    rng = np.random.default_rng(0)
    du, dp, u1bar = (jnp.asarray(rng.standard_normal(shape)) for shape in (u0.shape, p.shape, u0.shape))
    forward = jax.jit(lambda du, dp: jax.jvp(step, (u0, p), (du, dp))[1])(du, dp)
    u0bar, pbar = jax.jit(lambda c: step_transpose(tab, g, t0, h, u0, p, c))(u1bar)
    lhs, rhs = float(u1bar @ forward), float(u0bar @ du + pbar @ dp)
    # Relative to the sum of absolute products, so that a cancellation in the sum cannot pass a wrong transpose.
    scale = float(jnp.abs(u1bar) @ jnp.abs(forward))
    assert abs(lhs - rhs) <= 1e-10 * scale, (lhs, rhs, scale)


# About 50 s (three programs: the discrete adjoint, the forward solve, forward mode through it): kept out of the default suite, whose
# budget is 8 minutes on 2 cores (at 8:01 with the discrete adjoint's end-to-end tests in it); the
# default suite checks the discrete adjoint step by step (above).
@pytest.mark.slow
def test_discrete_adjoint_is_the_derivative_of_psi_on_the_forward_steps(problem):
    # Forward-mode differentiation (`jax.jacfwd`, diffrax's `ForwardMode`) through diffrax stepping exactly the
    # forward solve's accepted steps (`StepTo`), against the discrete adjoint. The adaptive solve ends the step
    # before the ramp's end at prevbefore(0.05) and starts the next at nextafter(0.05); `StepTo` gets both times
    # (its extra step of two ulps adds ~1e-17 of psi). Both differentiate the same discrete psi, the discrete
    # adjoint in reverse (the transposed steps), the reference in forward mode (tangents carried through the
    # steps): an independent route. Rounding accumulates over the ~900 steps, measured 1.2e-14 (scene) and
    # 5.7e-13 (initial state) of the largest entry (reverse mode through diffrax, the reference until 26 Nov:
    # 6e-15 and 4e-13). 1e-10 keeps three orders of margin against rounding, and a wrong term in the recursion
    # is O(1) (tests above). The switch-time handling (the step before the ramp's end recomputed up to
    # prevbefore(0.05)) is exercised, but the ramp law is C^3 at its end, so taking that step's last stages just
    # after the switch would change the gradient by far less than the tolerance.
    # Forward mode over the 82 float parameters and initial values compiles and runs in 18 s where reverse mode
    # through diffrax's checkpointed loop took 37 s to trace and compile (one core, quiet machine).
    kw = dict(rtol=RTOL, atol=ATOL, solver=fj.Rodas5P(), max_steps=4096)
    psi, grad = eqx.filter_jit(lambda pr: fj.DiscreteAdjoint().value_and_grad_problem(pr, **kw))(problem)

    obj = problem.objective
    forward = solve_minimal(problem.model, problem.scene, problem.t0, problem.t1, problem.y0, problem.z0,
                            integrand=obj.integrand, solver=fj.Rodas5P(), rtol=RTOL, atol=ATOL, dense=True,
                            max_steps=4096, jump_ts=problem.jump_ts)
    dense = forward.solution.interpolation
    ts = np.asarray(dense.ts[: int(dense.ts_size)])
    assert problem.jump_ts == (0.05,) and np.nextafter(0.05, 1.0) in ts
    ts = np.sort(np.append(ts, np.nextafter(0.05, 0.0)))
    field = _vector_field(problem)
    dynamic, static = eqx.partition((problem.scene, problem.objective), eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree((dynamic, problem.y0, problem.z0))

    def psi_on_steps(p):
        dynamic, y0, z0 = unravel(p)
        params = eqx.combine(dynamic, static)
        solution = diffrax.diffeqsolve(
            diffrax.ODETerm(lambda t, s, args: field(t, s, params)), fj.Rodas5P(), problem.t0, problem.t1, None,
            (y0, z0, jnp.zeros(())), stepsize_controller=diffrax.StepTo(jnp.asarray(ts)), max_steps=len(ts),
            adjoint=diffrax.ForwardMode())
        return solution.ys[2][-1], solution.ys[2][-1]

    g_flat, psi_steps = jax.jit(jax.jacfwd(psi_on_steps, has_aux=True))(flat)
    g_dynamic, g_y0, g_z0 = unravel(g_flat)
    np.testing.assert_allclose(float(psi), float(psi_steps), rtol=1e-13)
    assert_close_relative(jax.flatten_util.ravel_pytree(eqx.filter(grad.scene, eqx.is_inexact_array))[0],
                          jax.flatten_util.ravel_pytree(g_dynamic[0])[0], 1e-10, "scene gradient")
    assert_close_relative(jnp.concatenate([grad.y0, grad.z0]), jnp.concatenate([g_y0, g_z0]), 1e-10,
                          "initial-state gradient")


def test_discrete_adjoint_needs_a_rosenbrock_solver(problem):
    with pytest.raises(ValueError, match="Rosenbrock"):
        fj.DiscreteAdjoint().value_and_grad_problem(problem, rtol=RTOL, atol=ATOL, solver=diffrax.Dopri8(),
                                                    max_steps=4096)


# About 75 s (two gradient programs compiled): kept out of the default suite, as the test above.
@pytest.mark.slow
def test_terminal_term_and_velocity_integrand():
    # The rigid crank arm of tests/test_problem.py with its objective of the whole motion: a kinetic-energy
    # integral (velocities) plus a terminal tracking term, so that the end condition `(dG/dy, dG/dz, 1)` and
    # the terminal term's parameter derivatives are exercised. Against the paper's adjoint with Dopri8
    # (a different discretisation and method): both are accurate to about the tolerances (1e-10) times
    # the motion's conditioning; 1e-6 of the largest entry, as tests/test_problem.py allows between the
    # adjoint and autodiff, catches a missing terminal or velocity term (1e-2..1 there).
    from helpers import CRANK_ARM_POSITIONS, crank_arm_scene

    objective = fj.Objective(integrand=fj.KineticEnergy(),
                             terminal=fj.MarkerTracking(1, 1, fj.FixedPoint((0.25, -0.3))))
    problem = fj.Problem(crank_arm_scene(), 1.0, positions=CRANK_ARM_POSITIONS, velocities=[0.5], objective=objective)
    psi, grad = fj.value_and_grad(problem, method="discrete-adjoint", rtol=1e-10, atol=1e-12)
    psi_ref, grad_ref = fj.value_and_grad(problem, method=fj.Adjoint(rtol=1e-10, atol=1e-12), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(float(psi), float(psi_ref), rtol=1e-8)
    flat = lambda g: jax.flatten_util.ravel_pytree(eqx.filter(g, eqx.is_inexact_array))[0]
    assert_close_relative(flat(grad), flat(grad_ref), 1e-6, "discrete adjoint vs the paper's adjoint")
