"""Hard cases (issue 6): each gives a finite adjoint gradient that agrees with finite differences,
or, where the mechanism cannot be simulated, a clear error instead of a number.

Cases of one structure (`helpers.FAMILY`: 12 x 2 mesh, 4 modes, t1 = 0.15 s with a 0.05 s crank
run-up) share one compiled adjoint gradient and one compiled objective with the other test modules
(see `hard_cases.variant`). The members of other structures, each costing compilations of its own
(a very coarse mesh over two crank turns, 20 modes, a fine mesh, t1 = 30 s) are marked `slow` and
are rows of `benchmarks/bench_hard_cases.py`.

The comparison is with central differences of `psi` evaluated at rtol 1e-12 (a directional
derivative along a random direction and the largest gradient entry; one-sided at `x_min`), in
the max norm of the gradient: `|adjoint - fd| <= AGREEMENT_RTOL * max |grad|`.
"""

import equinox as eqx
import numpy as np
import pytest
from hard_cases import (adjoint_value_and_grad, adjoint_value_and_grad_for_run_time, agreement, crossing_design,
                        gradient_checks, tight_objective, variant, void_design)
from helpers import FAMILY, small_case, uniform_design

import ffr_jax

# Measured agreement on these cases is 1e-9…1e-7 (finite differences at rtol 1e-12 with a step
# of 1e-4 are good to ~1e-8); a NaN-free but wrong gradient, e.g. from a mishandled eigenvalue
# crossing, is off by far more.
AGREEMENT_RTOL = 1e-6
RUNTIME_ERRORS = (eqx.EquinoxRuntimeError, RuntimeError)

BASE = FAMILY


def slider_crank(**changes):
    args = {**BASE, **changes}
    return ffr_jax.cases.slider_crank(args.pop("nx"), args.pop("ny"), args.pop("n_modes"), args.pop("t1"), **args)


@pytest.fixture(scope="module")
def base():
    # The process-wide family member: its static parts (the partition's guess function, ...) are the
    # ones the shared compiled programs were built for, so these run without recompiling.
    return small_case()


def assert_gradient_agrees(case, x, gradient=adjoint_value_and_grad, **check_options):
    psi, grad = gradient(case, x)
    grad = np.asarray(grad)
    assert np.isfinite(float(psi)) and float(psi) > 0.0, f"psi = {float(psi)}"
    assert np.all(np.isfinite(grad)), "the adjoint gradient has non-finite entries"
    checks = gradient_checks(case, x, grad, **check_options)
    err = agreement(grad, checks)
    assert err <= AGREEMENT_RTOL, (
        f"adjoint vs finite differences: max |difference| / max |grad| = {err:.2e} > {AGREEMENT_RTOL:.0e}; "
        f"checks (what, adjoint, fd): {checks}"
    )
    return grad


def test_crossing_retained_eigenvalues(base):
    x, gap, pair = crossing_design(base)
    assert gap < 1e-10, f"the design should put eigenvalues {pair} on top of each other, relative gap {gap:.1e}"
    assert pair[1] < base.n_modes
    assert_gradient_agrees(base, x)


def test_void_regions_at_x_min(base):
    x = void_design(base)
    assert np.sum(np.asarray(x) == base.material.x_min) >= 4
    grad = assert_gradient_agrees(base, x)
    voids = np.asarray(x) == base.material.x_min
    # Voids carry almost no inertia or stiffness; their sensitivities are small but not zero.
    assert 0.0 < np.max(np.abs(grad[voids])) < np.max(np.abs(grad))


def test_crank_speed_at_first_resonance(base):
    x = uniform_design(base)
    first = float(base.frequencies(x)[0])
    resonant = variant(base, slider_crank(speed=2 * np.pi * first))
    static = float(tight_objective(base, x))
    assert float(tight_objective(resonant, x)) > 100 * static, "the resonant crank speed should excite the rod"
    assert_gradient_agrees(resonant, x)


def test_near_dead_point(base):
    # eps / l = 0.98: at phi = pi/2 the rod stands at 78.5 degrees and the slider's constraint
    # Jacobian with respect to theta is l cos(theta) = 0.2 l.
    near = variant(base, slider_crank(eccentricity=0.98))
    assert_gradient_agrees(near, uniform_design(base))


def test_dead_point_reached_is_a_clear_error():
    # eps = l: the rod would stand upright with its slider at the dead point (cos theta = 0).
    with pytest.raises(ValueError, match=r"eccentricity must lie in \(0, l\)"):
        slider_crank(eccentricity=1.0)


def test_dead_point_limit_during_motion_is_a_clear_error(base):
    # eps / l = 0.99 at full speed: the flexible rod is pulled through the dead point; the
    # simulation stops with the partition check (or Newton's) rather than returning a number.
    beyond = variant(base, slider_crank(eccentricity=0.99))
    with pytest.raises(RUNTIME_ERRORS, match="partition became singular|did not converge"):
        adjoint_value_and_grad(beyond, uniform_design(base))


@pytest.mark.slow  # a structure of its own (two compilations, ~25 s); a row of benchmarks/bench_hard_cases.py
def test_coarse_mesh_longer_horizon():
    # 4 x 2 elements (4 design variables), 3 modes, 0.4 s: nearly three times the base horizon,
    # two crank turns; every entry against finite differences. Stand-in for t1 = 30 s (slow below).
    case = slider_crank(nx=4, n_modes=3, t1=0.4, t_ramp=0.1)
    x = case.initial_design(0.5) + np.array([0.1, -0.1, 0.2, -0.2])
    assert_gradient_agrees(case, x, n_directions=0, n_entries=case.n_design)


@pytest.mark.slow
def test_many_retained_modes():
    # 20 of the 75 free dofs (highest retained frequency ~6.5 kHz, 17 times the 4-mode case's).
    # 30 modes works the same way but its adjoint gradient takes over half an hour here.
    # Its own structure, run-heavy (Dopri8 at its stability limit): compiled for run time, the eight tight solves
    # batched, as test_long_horizon below (34-35 s -> 29 s on one quiet core; the coarse and fine meshes got slower so).
    case = slider_crank(n_modes=20)
    assert_gradient_agrees(case, case.initial_design(0.5), adjoint_value_and_grad_for_run_time, batched=True)


@pytest.mark.slow
def test_fine_mesh():
    case = slider_crank(nx=48, ny=4, n_modes=6)
    assert_gradient_agrees(case, void_design(case))


@pytest.mark.slow
def test_long_horizon():
    # The largest entry and one random direction (two fourth-order central differences, eight tight 30-s solves):
    # every entry (ten solves, 271 s of CI's slow set) added no check that the direction does not make; each entry
    # is checked against finite differences on the shorter horizon above.
    # The cost is running the solves, not compiling them (one core, quiet: the adjoint gradient compiles in 11 s and
    # runs in 30 s, a tight solve 3 s and 8 s): both programs are compiled for run time (hard_cases.RUN_TIME_OPTIONS;
    # neither is shared with another test, t1 = 30 s is a structure of its own), and the eight solves run as one
    # vmapped batch (each with its own steps; same values to round-off, 1e-14 of psi measured). 119 s -> 51 s.
    case = slider_crank(nx=4, n_modes=2, t1=30.0, t_ramp=2.0)
    assert_gradient_agrees(case, case.initial_design(0.5), adjoint_value_and_grad_for_run_time, batched=True)
