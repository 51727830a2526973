"""The default route of `value_and_grad` (`ffr_jax/_sensitivity/_route.py`) and the compile message.

The route's numbers (cost and accuracy on the reference case at 6, 15 and 30 modes) are measured in
benchmarks/RESULTS.md, "Default route"; here: the stability bound it rests on, which route each kind
of problem takes, that the route is the one run, and that a first call says once that it compiles.
"""

import logging

import numpy as np
import pytest
from diffrax._solver import dopri8

import ffr_jax as fj
from ffr_jax._api import _route
from ffr_jax._sensitivity import _route as route_module

from helpers import CRANK_ARM_POSITIONS, crank_arm_scene, small_case


def _stability_function(tableau):
    s = len(tableau.b_sol)
    a = np.zeros((s, s))
    for i, row in enumerate(tableau.a_lower):
        a[i + 1, : len(row)] = row
    b = np.asarray(tableau.b_sol)
    return lambda z: 1 + z * b @ np.linalg.solve(np.eye(s) - z * a, np.ones(s))


def test_dopri8_imaginary_stability_bound_from_its_tableau():
    """`y_stab`: |R(iy)| of Dopri8 stays within 1 + 1e-7 up to y_stab and exceeds 1 just beyond.

    The constant is quoted to two decimals; a grid of 1e-3 locates the crossing well inside that.
    """
    tableau = dopri8._dopri8_tableau
    r = _stability_function(tableau)
    y_stab = route_module.DOPRI8_IMAGINARY_STABILITY
    inside = np.linspace(1e-3, y_stab - 0.005, 3000)
    assert max(abs(r(1j * y)) for y in inside) <= 1 + 1e-7, "Dopri8 unstable below the quoted bound"
    assert abs(r(1j * (y_stab + 0.01))) > 1, "Dopri8 still stable past the quoted bound"


def test_reference_case_takes_the_stiff_route():
    """6 modes up to 726 Hz (REFERENCE_CASE §2) over 3 s: N_stab = 2 pi 726 * 3 / 3.7 = 3,700 steps."""
    route = fj.choose_route(fj.cases.slider_crank())
    assert route.stiff and isinstance(route.method, fj.DiscreteAdjoint) and isinstance(route.solver, fj.Rodas5P)
    # The frequencies are the template's (x = 0.5): REFERENCE_CASE §2 gives 726 Hz to three digits.
    assert abs(route.omega_max / (2 * np.pi) - 726) < 1, route.reason
    assert (route.rtol, route.atol) == (route_module.STIFF_RTOL, route_module.STIFF_ATOL)
    assert "stiff route" in route.reason and "726" in route.reason


def test_short_or_rigid_problems_take_the_explicit_route():
    flexible = fj.choose_route(small_case())  # 0.15 s: a few hundred stability-bound steps at most
    assert not flexible.stiff and isinstance(flexible.method, fj.Adjoint) and flexible.solver is None
    assert 0 < flexible.stability_steps <= route_module.STIFF_STEPS
    rigid = fj.Problem(crank_arm_scene(), 1.0, positions=CRANK_ARM_POSITIONS, velocities=[0.5],
                       objective=fj.Objective(integrand=fj.KineticEnergy()))
    route = fj.choose_route(rigid)
    assert not route.stiff and route.omega_max == 0.0 and "no retained modes" in route.reason


def test_given_options_override_the_route():
    case = fj.cases.slider_crank(4, 2, 2, 3.0)  # a stiff member: 316 Hz over 3 s, ~1,600 steps
    method, solver, rtol, atol, _ = _route(case, None, None, None, None)
    assert isinstance(method, fj.DiscreteAdjoint) and isinstance(solver, fj.Rodas5P)
    assert (rtol, atol) == (route_module.STIFF_RTOL, route_module.STIFF_ATOL)
    # rtol alone: the route's method and solver, atol two decades below rtol (as both routes' defaults).
    assert _route(case, None, None, 1e-9, None)[2:4] == (1e-9, 1e-9 / 100)
    # A method given: that method at the paper's tolerances, whatever the route.
    method, solver, rtol, atol, _ = _route(case, "autodiff", None, None, None)
    assert isinstance(method, fj.Autodiff) and solver is None and (rtol, atol) == (1e-10, 1e-12)
    # A solver given without a method: the paper's adjoint with that solver.
    method, solver, *_ = _route(case, None, fj.Rodas5P(), None, None)
    assert isinstance(method, fj.Adjoint) and isinstance(solver, fj.Rodas5P)


def test_first_call_says_it_compiles_once(caplog):
    """A `Program` (what every public function runs) logs "compiling ..." and the time before and after
    its first call for a structure and shapes, nothing on later calls with other values, and again for
    new shapes. (A trivial function: the mechanism, not a solver's compile time, is under test.)"""
    import jax.numpy as jnp

    from ffr_jax._compiled import Program

    program = Program(lambda a, scale: scale * jnp.sin(a), "a test program")
    with caplog.at_level(logging.INFO, logger="ffr_jax"):
        program(jnp.ones(3), 2.0)
        program(jnp.zeros(3), 2.0)      # same shapes and static values: no message
        program(jnp.ones(4), 2.0)       # new shapes: compiles again
    messages = [r.getMessage() for r in caplog.records if r.name == "ffr_jax"]
    assert sum(m.startswith("compiling a test program") for m in messages) == 2, messages
    assert sum("compiled and ran in" in m for m in messages) == 2, messages


def test_public_functions_run_programs_that_say_when_they_compile():
    from ffr_jax import _api
    from ffr_jax._compiled import Program

    for name in ("_simulate_problem", "_simulate_case", "_value_and_grad_problem", "_value_and_grad_design",
                 "_value_and_grad_scene"):
        assert isinstance(getattr(_api, name), Program), name


@pytest.fixture(scope="module")
def probe_20_modes():
    """Issue 32's probe: 20 modes on the 12 x 2 rod over 0.2 s (highest mode ~tens of kHz: stiff), at x = 0.5,
    with psi's directional derivative along a fixed +-1 direction by central differences at rtol 1e-12."""
    case = fj.cases.slider_crank(12, 2, 20, 0.2)
    x = case.initial_design(0.5)
    d = np.random.default_rng(0).choice([-1.0, 1.0], size=case.n_design)
    h = 1e-4
    psi = [float(fj.objective(case, x + s * h * d, rtol=1e-12, atol=1e-16)) for s in (1, -1)]
    return case, x, d, (psi[0] - psi[1]) / (2 * h)


@pytest.mark.slow
# Not "direct": forward sensitivities take one tangent per scene parameter (1,385 at 20 modes) and ran for over
# 6 minutes here without finishing; "fd" is the reference itself.
@pytest.mark.parametrize("method", ["adjoint", "autodiff", "backsolve", "discrete-adjoint", None])
def test_every_method_at_20_modes_is_right_or_raises(probe_20_modes, method):
    """Every method with its default settings is right (its directional derivative within 1e-4 of max |g| |d|_1
    of the central difference, which is good to ~1e-8 there: step 1e-4, psi at rtol 1e-12) or raises.

    Autodiff through Dopri8 at its stability limit returned a gradient 530x too large here (benchmarks/RESULTS.md,
    "Every method at 20 modes against finite differences"); it is now checked by default and raises."""
    case, x, d, fd = probe_20_modes
    try:
        _, grad = fj.value_and_grad(case, x, method)
    except ValueError as err:
        assert method == "autodiff" and "Untrustworthy gradient" in str(err), f"{method}: {err}"
        return
    g = np.asarray(grad)
    assert abs(float(g @ d) - fd) <= 1e-4 * np.max(np.abs(g)) * np.sum(np.abs(d)), (method, float(g @ d), fd)
