"""Spatial bad input (issue 26, Must show): an assembly that cannot close is refused at `fj.Problem` with the
constraints that stay violated named; a spatial slider–crank driven into its dead point stops with the in-program
dead-point error (`benchmarks/RESULTS.md`, "Bad input", for the planar counterparts in tests/test_simulation_errors.py
and tests/test_hard_cases.py).
"""

import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._spatial._angle_driver import EulerNormalisation

RUNTIME_ERRORS = (fj.SimulationError, RuntimeError)
LENGTH, WALL = 0.2, 1.0


def _bar_and_wall(wall: float):
    """A rigid bar of length `LENGTH` hinged to the ground about `z` at the origin, its tip on the plane `x = wall`:
    it closes for `wall <= LENGTH` and cannot close for `wall > LENGTH` (the tip reaches `x <= LENGTH` only)."""
    bar = fj.Body("bar", fj.spatial_rigid_body_data(1.0, (LENGTH / 2, 0.0, 0.0), np.diag([2e-4, 1.4e-2, 1.4e-2]),
                                                    [(0.0, 0.0, 0.0), (LENGTH, 0.0, 0.0)]))
    scene = fj.Scene(bodies=(bar,), constraints=(
        fj.SpatialRevolute(0, 0, (0.0, 0.0, 1.0)), EulerNormalisation(0),
        fj.SpatialPointOnPlane(0, 1, point=(wall, 0.0, 0.0), normal=(1.0, 0.0, 0.0))))
    # Turned by 0.5 rad about z: the tip's x then varies with the turn (at 0 rad it is at its largest, a dead point).
    positions = np.array([0.0, 0.0, 0.0, np.cos(0.25), 0.0, 0.0, np.sin(0.25)])
    return fj.Problem(scene, 0.1, positions=positions, objective=fj.KineticEnergy())


@pytest.mark.slow  # ~5 s CPU (the Problem's compilations and the least-squares diagnosis' residual)
def test_assembly_that_cannot_close_names_the_violated_constraints():
    # The tip misses the wall by WALL - LENGTH = 0.8 at best (bar along x). Least squares over the bar's R and p shares
    # that gap between the loop's two equations of unit weight that carry it, the hinge's x row and the plane's row:
    # min a^2 + (0.8 - a)^2 at a = 0.4 each. The Euler normalisation is met there, so it is not named.
    with pytest.raises(ValueError, match="cannot be assembled at the initial state") as err:
        _bar_and_wall(WALL)
    message = str(err.value)
    assert "constraint 0 SpatialRevolute(body_i = 'bar')" in message
    assert "constraint 2 SpatialPointOnPlane(body = 'bar')" in message
    assert "EulerNormalisation" not in message
    assert f"largest residual {(WALL - LENGTH) / 2:.3g}" in message



@pytest.mark.slow  # compiles the spatial slider-crank's forward program (~25 s on a quiet machine, RESULTS)
def test_spatial_dead_point_during_motion_is_a_clear_error():
    # The planar counterpart (tests/test_hard_cases.py): eccentricity 0.99 l at full speed pulls the flexible rod
    # through the dead point (the rigid rod would stand at 81.9 degrees at phi = pi/2; the inertia loads of the full
    # speed bend it past upright). The spatial case integrates the same equations, so it must stop the same way,
    # with the dead-point (singular partition) or Newton error, never with a number.
    case = fj.cases.slider_crank(4, 2, 2, 0.15, t_ramp=0.05, eccentricity=0.99, spatial=True)
    with pytest.raises(RUNTIME_ERRORS, match="partition became singular|did not converge"):
        fj.objective(case, case.initial_design(0.5))
