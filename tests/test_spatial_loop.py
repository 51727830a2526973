"""A spatial closed loop (issue 26, first part): the RSSR four-bar `fj.cases.spatial_four_bar` of rigid spatial
bodies assembles consistently, keeps its joints closed and conserves its energy while the crank turns fully.

Marked slow: building the problem and compiling its solve take 30-80 s on the shared 2-core machine (the suite
sits at its time budget); the 10 s run is in benchmarks/RESULTS.md ("Spatial four-bar").
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj

RTOL, ATOL = 1e-10, 1e-12
# Newton's method for the dependent coordinates stops at 1e-13 (1 + |y_d|); the joints' residuals are of the
# size of that, far below 1e-10, at every output time.
CLOSURE_TOL = 1e-10
# Integrated at rtol 1e-10 over ~100-200 Dopri8 steps: global error ~ 1e-8 of the state; the energy (scaled by
# itself) drifts by that much at most. A wrong constraint force or a jump to the other assembly branch changes it
# at the percent level.
SOLVER_DRIFT = 1e-7


@eqx.filter_jit
def _energy_and_closure(problem, positions, velocities):
    scene = problem.scene

    def one(y, z):
        energy = scene.kinetic_energy(y, z) + scene.potential_energy(jnp.zeros(()), y)
        return energy, jnp.max(jnp.abs(scene.constraint_residual(jnp.zeros(()), y)))

    return jax.vmap(one)(positions, velocities)


@pytest.fixture(scope="module")
def four_bar():
    problem = fj.cases.spatial_four_bar(1.0)
    traj = fj.simulate(problem, ts=jnp.linspace(0.0, 1.0, 51), rtol=RTOL, atol=ATOL)
    energy, closure = _energy_and_closure(problem, traj.positions, traj.velocities)
    return problem, traj, np.asarray(energy), np.asarray(closure)


@pytest.mark.slow
def test_spatial_four_bar_assembles_and_stays_closed(four_bar):
    """The initial state satisfies the position and velocity constraints; the joints stay closed; the crank
    turns more than once (so the check covers every crank angle)."""
    problem, traj, _, closure = four_bar
    y_r0, z_r0 = problem.initial_state()
    scene = problem.scene
    assert float(jnp.max(jnp.abs(scene.constraint_residual(jnp.zeros(()), y_r0)))) <= CLOSURE_TOL
    assert float(jnp.max(jnp.abs(problem.model.velocity_constraint(jnp.zeros(()), y_r0, z_r0, scene)))) <= CLOSURE_TOL
    assert np.max(closure) <= CLOSURE_TOL
    p = np.asarray(traj.positions)[:, 3:7]  # the crank's Euler parameters: a turn about z by 2 atan2(e3, e0)
    turns = np.ptp(np.unwrap(2.0 * np.arctan2(p[:, 3], p[:, 0]))) / (2 * np.pi)
    assert turns > 1.0, f"the crank turned {turns} times"


@pytest.mark.slow
def test_spatial_four_bar_conserves_energy(four_bar):
    """`T + V` of the free linkage under gravity stays constant."""
    _, _, energy, _ = four_bar
    assert np.ptp(energy) <= SOLVER_DRIFT * np.max(np.abs(energy)), f"energy drifts by {np.ptp(energy)}"
