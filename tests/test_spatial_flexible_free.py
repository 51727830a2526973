"""A free flexible spatial body (issue 26): no joints, no forces, an initial spin about a non-principal axis and an
initial elastic velocity. Energy (kinetic + strain), linear momentum and angular momentum about the origin are
constants of its motion, so they are conserved along the numerical solution to the solver's accuracy.

The body: point masses at random positions in 3D with random (out-of-plane) mode shapes, so every invariant
(`C0`, `C1`, `C2`, the gyroscopic coupling) is non-zero. What this check cannot see: a wrong force that does no
work and acts on the modal coordinates only (the skew Coriolis term `2 w . ax(C2) qdot` of `h_q` with the wrong
sign passes it: internal, power-free); `test_spatial_flexible_body.py` checks every term node by node. (A wrong
sign of the Coriolis moment in `h_w` drifts the energy by 0.7 here.) Marked slow: compiling the solve costs ~10-20 s.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._spatial import _flexible_body as flex

RTOL, ATOL = 1e-10, 1e-12
# Integrated at rtol 1e-10 over ~100-300 Dopri steps: the global error of the state is ~1e-8 of its size, and the
# invariants (smooth functions of the state, scaled by their own size) drift by that much at most. A missing or
# wrong gyroscopic or Coriolis term changes them at the 1e-2 level over this motion (the spin carries the energy).
SOLVER_DRIFT = 1e-7


def _free_body_problem(t1=1.0):
    rng = np.random.default_rng(7)
    n_nodes, n_q = 6, 2
    masses = rng.uniform(0.5, 1.5, n_nodes)
    positions = rng.normal(size=(n_nodes, 3)) * np.array([0.5, 0.3, 0.2])
    modes = 0.2 * rng.normal(size=(n_nodes, 3, n_q))
    # Modal frequencies of a few Hz: the elastic vibration and the spin (~2 rad/s) interact over the run.
    stiffness = np.diag([40.0, 90.0])
    data = fj.spatial_flexible_body_data(masses, positions, modes, stiffness, markers=(0,))
    scene = fj.Scene(bodies=(fj.Body("free", data),), constraints=())
    p0 = fj.euler_parameters((0.3, -0.5, 1.0), 0.7)
    spin = np.array([1.0, 0.7, 2.0])  # body frame, not along a principal axis of J0
    velocities = np.concatenate([[0.1, -0.2, 0.05], np.asarray(fj.euler_parameter_rates(p0, spin)), [0.5, -0.3]])
    positions0 = np.concatenate([[0.2, 0.0, -0.1], p0, [0.01, -0.02]])
    return fj.Problem(scene, t1, positions=positions0, velocities=velocities, objective=fj.KineticEnergy())


@eqx.filter_jit
def _invariants(data, positions, velocities):
    def one(y, z):
        energy = flex.kinetic_energy(data, y, z) + flex.strain_energy(data, y)
        lin, ang = flex.momenta(data, y, z)
        return energy, lin, ang

    return jax.vmap(one)(positions, velocities)


@pytest.fixture(scope="module")
def motion():
    problem = _free_body_problem()
    traj = fj.simulate(problem, ts=jnp.linspace(0.0, problem.t1, 41), rtol=RTOL, atol=ATOL)
    data = problem.scene.bodies[0].data
    energy, lin, ang = _invariants(data, traj.positions, traj.velocities)
    return problem, traj, np.asarray(energy), np.asarray(lin), np.asarray(ang)


@pytest.mark.slow
def test_free_flexible_body_conserves_energy_and_momenta(motion):
    problem, traj, energy, lin, ang = motion
    q = np.asarray(traj.positions)[:, 7:]
    assert np.ptp(q, axis=0).min() > 1e-3, "the body vibrates (an elastic motion to conserve energy through)"
    spin = np.asarray(traj.positions)[:, 3:7]
    assert np.min(np.abs(spin @ spin[0] / np.sum(spin[0] ** 2))) < 0.9, "the body turns by a large angle"
    assert np.ptp(energy) <= SOLVER_DRIFT * np.max(np.abs(energy)), f"energy drifts by {np.ptp(energy)}"
    for name, v in (("linear momentum", lin), ("angular momentum", ang)):
        drift = np.max(np.ptp(v, axis=0))
        assert drift <= SOLVER_DRIFT * np.max(np.abs(v)), f"{name} drifts by {drift}"
    # The radial rate of the Euler parameters vanishes exactly: |p| keeps its initial 1.
    norms = np.linalg.norm(np.asarray(traj.positions)[:, 3:7], axis=1)
    assert np.max(np.abs(norms - 1.0)) <= SOLVER_DRIFT, "|p| drifts"
