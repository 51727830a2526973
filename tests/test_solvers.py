"""The stiff solvers of `ffr_jax` (linearly implicit Rosenbrock methods) as diffrax solvers.

Checked against problems with known solutions: the classical order of the solution and of the
dense output (step halving), large steps on a stiff undamped oscillator driven slowly (the
situation of highly stiff retained modes), derivatives through every diffrax adjoint against the
closed form, and psi of a small slider–crank against Dopri8 at a tight tolerance.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax
from ffr_jax._solver import Rodas4, Rodas5P

from helpers import small_case

SOLVERS = [Rodas4(), Rodas5P()]
IDS = [type(s).__name__ for s in SOLVERS]


def _nonautonomous(t, y, args):
    """`u' = v, v' = -u, w' = -2 t w`: `(cos t, -sin t, exp(-t^2))` from `(1, 0, 1)`."""
    u, v, w = y
    return v, -u, -2 * t * w


def _exact(t):
    return jnp.cos(t), -jnp.sin(t), jnp.exp(-(t**2))


def _fixed_step_errors(solver, n_steps):
    """Max error at `t = 2` and max error of the dense output on 401 points, with `n_steps` steps."""
    sol = diffrax.diffeqsolve(diffrax.ODETerm(_nonautonomous), solver, 0.0, 2.0, 2.0 / n_steps, (1.0, 0.0, 1.0),
                              stepsize_controller=diffrax.ConstantStepSize(),
                              saveat=diffrax.SaveAt(t1=True, dense=True), max_steps=n_steps)
    end = max(float(jnp.abs(a[-1] - b)) for a, b in zip(sol.ys, _exact(2.0)))
    ts = jnp.linspace(0.0, 2.0, 401)
    dense = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(jax.vmap(sol.evaluate)(ts), _exact(ts)))
    return end, dense


@pytest.mark.parametrize("solver", SOLVERS, ids=IDS)
def test_order_of_convergence_of_solution_and_dense_output(solver):
    # The `w` component needs the `h d_i f_t` terms of a non-autonomous problem for full order.
    # Step halving 2/80 -> 2/160 lies in the asymptotic range (errors 3e-12 and more, far above
    # round-off); the next term of the error expansion moves the observed order by O(h) ~ 0.05,
    # so 0.25 separates the tableau's order from one order less with a wide margin.
    (e1, d1), (e2, d2) = _fixed_step_errors(solver, 80), _fixed_step_errors(solver, 160)
    tab = solver.tableau
    assert abs(np.log2(e1 / e2) - tab.order) < 0.25, f"solution order {np.log2(e1 / e2):.2f} != {tab.order}"
    dense = min(tab.order, tab.dense_order + 1)
    assert abs(np.log2(d1 / d2) - dense) < 0.25, f"dense-output order {np.log2(d1 / d2):.2f} != {dense}"


def _slow_and_stiff_modes(t, y, omega):
    """A slow mode `q1` coupled to a stiff undamped mode `q2` of frequency `omega`, both driven slowly."""
    q1, q2, p1, p2 = y
    return p1, p2, -q1 + jnp.sin(2 * t) + 0.1 * omega**2 * q2, -(omega**2) * q2 + jnp.sin(t) + q1


def _slow_limit(t):
    """`q1` of the limit `omega -> inf`: `q2 -> 0`, `0.1 omega^2 q2 -> 0.1 (sin t + q1)`, so
    `q1'' + 0.9 q1 = sin 2t + 0.1 sin t` from rest."""
    a, b = -1 / 3.1, -1.0
    c = -(2 * a + b) / np.sqrt(0.9)
    return a * jnp.sin(2 * t) + b * jnp.sin(t) + c * jnp.sin(np.sqrt(0.9) * t)


@pytest.mark.parametrize("solver", SOLVERS, ids=IDS)
def test_stiff_undamped_mode_costs_steps_set_by_the_slow_dynamics(solver):
    # The situation of highly stiff retained modes: at omega = 1e6 an explicit method needs about
    # omega T / 3 ~ 3e6 steps (stability); an L-stable method takes steps set by the slow mode
    # (measured: 119 Rodas5P, 449 Rodas4, the same as at omega = 1e4). 1,000 steps is thousands
    # of times fewer than the stability limit. Reference: the closed-form limit omega -> inf, which
    # differs from the omega = 1e6 system by O(omega^-2) = 1e-12 (from rest, the stiff mode's free
    # oscillation is excited at amplitude 1e-12 / omega); rtol = atol = 1e-8 gives a global error
    # of a few rtol over 10 rad (measured 1.9e-8, 4.6e-9), so 1e-7 leaves a margin of five.
    ts = jnp.linspace(0.0, 10.0, 101)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(_slow_and_stiff_modes), solver, 0.0, 10.0, None, (0.0,) * 4,
                              args=1e6, saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8), max_steps=10_000)
    assert int(sol.stats["num_steps"]) < 1_000
    error = float(jnp.max(jnp.abs(sol.ys[0] - _slow_limit(ts))))
    assert error < 1e-7, f"error {error:.2e} of the slow mode"


def _oscillator_end(k, solver, adjoint):
    """`y(T)` of `y'' = -k y`, `y(0) = 1`, `y'(0) = 0`: `cos(sqrt(k) T)`."""
    sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, k: (y[1], -k * y[0])), solver, 0.0, 2.0, None,
                              (jnp.ones(()), jnp.zeros(())), args=k,
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12),
                              adjoint=adjoint, max_steps=20_000)
    return sol.ys[0][-1]


@pytest.mark.parametrize("adjoint", [diffrax.RecursiveCheckpointAdjoint(), diffrax.ForwardMode(),
                                     diffrax.BacksolveAdjoint(stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12))],
                         ids=["autodiff", "forward", "backsolve"])
def test_derivative_through_every_diffrax_adjoint(adjoint):
    # d/dk cos(sqrt(k) T) = -sin(sqrt(k) T) T / (2 sqrt(k)); at rtol 1e-10 the solution and its
    # derivative are accurate to about 1e-9 relative (the order-5 error estimate is conservative),
    # so 1e-7 leaves two orders for the derivative's own discretisation error.
    k, t1 = jnp.asarray(3.0), 2.0
    solver = Rodas5P()
    if isinstance(adjoint, diffrax.ForwardMode):
        value, derivative = jax.jvp(lambda kk: _oscillator_end(kk, solver, adjoint), (k,), (jnp.ones(()),))
    else:
        value, derivative = jax.value_and_grad(_oscillator_end)(k, solver, adjoint)
    exact = -jnp.sin(jnp.sqrt(k) * t1) * t1 / (2 * jnp.sqrt(k))
    assert abs(float(value) - float(jnp.cos(jnp.sqrt(k) * t1))) < 1e-8
    assert abs(float(derivative - exact)) < 1e-7 * abs(float(exact))


def test_psi_of_a_small_slider_crank_agrees_with_dopri8():
    # Reference: Dopri8 at rtol 1e-12 (psi to about 1e-14 relative, benchmarks/RESULTS.md). The
    # global error of an adaptive solve is of the order of its rtol in the components that carry
    # psi (measured here: 1.1e-10 at rtol 1e-10, 4e-8 at 1e-8, 1.8e-5 at 1e-6 with atol = 1e-2 rtol,
    # psi = 6e-8 being small); 1e-8 at rtol 1e-10 allows two orders above the measured error.
    case = small_case(10, 2, 3, 0.2)
    x = case.initial_design(0.5)
    reference = float(ffr_jax.objective(case, x, rtol=1e-12, atol=1e-14))
    trajectory = ffr_jax.simulate(case, x, rtol=1e-10, atol=1e-12, solver=Rodas5P())
    assert abs(float(trajectory.psi) - reference) < 1e-8 * abs(reference)
