"""Rigid spatial bodies (issue 26, first part): Euler-parameter kinematics, the equations of motion
against an independent point-mass Lagrangian, a hinge's first acceleration against Euler's equation,
the heavy symmetric top (steady precession against the analytic rate; energy and the two conserved
angular momenta of a nutating top), and bad input.

The reference model is written from scratch: a rigid body is a cloud of point masses `m_k` at body
points `u_k`, each at `r_k = R + A u_k` with `A u = u + 2 e0 (e x u) + 2 e x (e x u)` for `(e0, e) = p / |p|`
(the vector form of the rotation, coded independently of the matrix form of the package). Its mass
matrix and quadratic-velocity forces come from automatic differentiation of
`T = sum_k 1/2 m_k |rdot_k|^2 + 1/2 k (p . pdot / |p|)^2`, the last term being the package's radial
gauge term (see `ffr_jax._spatial._rigid_body`).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._dynamics._model import MinimalModel, choose_partition
from ffr_jax._dynamics._body_dynamics import body_inertia_and_elastic_forces, body_mass_matrix, marker_position
from ffr_jax._spatial import _rigid_body
from ffr_jax._spatial._euler_parameters import angular_velocity, rotation_matrix

# Tolerances, named for what they bound.
ROUND_OFF = 1e-12  # closed-form identities and the body-data equations against autodiff: a few dozen flops each
# The top is integrated at rtol 1e-10 / atol 1e-12 (Dopri8, ~80 steps over 1 s). Each step commits a local
# error ~ rtol |y|, so the global error of the state is ~ 1e-8; conserved quantities and the steady-precession
# angle are smooth functions of the state of size 1 (scaled), so they drift by ~ 1e-8 at most. A sign error in
# the gyroscopic term, or a missing one, changes the precession rate at the 10 % level and the momenta at
# the percent level within one precession period.
SOLVER_DRIFT = 1e-7
RTOL, ATOL = 1e-10, 1e-12

# The heavy symmetric top: a disc of radius r on a massless stem, centre of mass at l on the symmetry axis
# (body z) from the tip, which is the body-frame origin and sits on a frictionless ground socket.
MASS, RADIUS, LENGTH, G = 1.0, 0.1, 0.1, 9.81
I3 = 0.5 * MASS * RADIUS**2  # about the symmetry axis
I1 = 0.25 * MASS * RADIUS**2 + MASS * LENGTH**2  # transverse, about the tip (parallel axes)
TILT, SPIN = 0.5, 60.0  # theta from the vertical; omega3, the angular velocity component along the axis
T1 = 1.0


def _point_cloud(seed: int):
    """Eight point masses and their body data (mass, first moment, inertia about the frame origin)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(8, 3)) * np.array([0.3, 0.2, 0.1]) + np.array([0.1, -0.05, 0.2])
    m = rng.uniform(0.5, 2.0, size=8)
    inertia = np.einsum("k,kij->ij", m, np.einsum("ki,ki->k", u, u)[:, None, None] * np.eye(3) - u[:, :, None] * u[:, None, :])
    data = fj.spatial_rigid_body_data(m.sum(), m @ u, inertia, u[:2])
    return u, m, data


def _rotate(p, u):
    """`A(p / |p|) u` in the vector form `u + 2 e0 (e x u) + 2 e x (e x u)` (independent of the package)."""
    q = p / jnp.linalg.norm(p)
    e0, e = q[0], q[1:]
    c = jnp.cross(jnp.broadcast_to(e, u.shape), u)
    return u + 2 * e0 * c + 2 * jnp.cross(jnp.broadcast_to(e, u.shape), c)


def _reference_energy(u, m, k):
    def energy(y, z):
        rdot = jax.jvp(lambda yy: yy[:3] + _rotate(yy[3:], u), (y,), (z,))[1]
        rho = y[3:] @ z[3:] / jnp.linalg.norm(y[3:])
        return 0.5 * jnp.sum(m[:, None] * rdot**2) + 0.5 * k * rho**2
    return energy


def _random_state(seed: int):
    """A state with `|p| != 1` and a radial rate: the equations hold off the unit sphere too."""
    rng = np.random.default_rng(seed)
    y = jnp.asarray(np.concatenate([rng.normal(size=3), 1.3 * fj.euler_parameters(rng.normal(size=3), 2.0)]))
    return y, jnp.asarray(rng.normal(size=7))


def test_euler_parameter_kinematics():
    """`A` is a rotation, `A^T Adot = omega'~` with `omega' = 2 G pdot / |p|^2`, and the rates of a body
    angular velocity reproduce it."""
    y, z = _random_state(0)
    p, pdot = y[3:], z[3:]
    a, adot = jax.jvp(rotation_matrix, (p,), (pdot,))
    np.testing.assert_allclose(a.T @ a, np.eye(3), atol=ROUND_OFF)
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=ROUND_OFF)
    w = a.T @ adot
    omega = angular_velocity(p, pdot)
    np.testing.assert_allclose(w, -w.T, atol=ROUND_OFF)
    np.testing.assert_allclose([w[2, 1], w[0, 2], w[1, 0]], omega, atol=ROUND_OFF)
    np.testing.assert_allclose(jax.vmap(lambda v: _rotate(p, v))(jnp.eye(3)).T, a, atol=ROUND_OFF)
    unit = p / jnp.linalg.norm(p)
    rates = fj.euler_parameter_rates(unit, omega)
    np.testing.assert_allclose(unit @ rates, 0.0, atol=ROUND_OFF)
    np.testing.assert_allclose(angular_velocity(unit, rates), omega, atol=ROUND_OFF)


def test_equations_of_motion_match_point_mass_lagrangian():
    """`M_b` and `h_omega` of the body data equal `d2T/dz2` and `(d2T/dz dy) z - dT/dy` of the point-mass
    reference, and gravity's generalized force equals `sum_k m_k (dr_k/dy)^T g`, at a state off the unit sphere."""
    u, m, data = _point_cloud(1)
    y, z = _random_state(2)
    g = jnp.array([0.3, -1.0, -9.81])
    k = 4.0 * np.trace(np.asarray(data.inertia)) / 3.0
    (m_b, h_b, q_b, r_b, t_b), (m_ref, h_ref, q_ref, r_ref, t_ref) = _both_models(data, jnp.asarray(u), jnp.asarray(m),
                                                                                 k, y, z, g)
    np.testing.assert_allclose(m_b, m_ref, atol=ROUND_OFF * np.max(np.abs(m_ref)))
    np.testing.assert_allclose(h_b, h_ref, atol=ROUND_OFF * np.max(np.abs(h_ref)))
    np.testing.assert_allclose(q_b, q_ref, atol=ROUND_OFF * np.max(np.abs(q_ref)))
    np.testing.assert_allclose(r_b, r_ref, atol=ROUND_OFF)
    np.testing.assert_allclose(t_b, t_ref, rtol=ROUND_OFF)
    assert np.min(np.linalg.eigvalsh(np.asarray(m_b))) > 0.0


@jax.jit
def _both_models(data, u, m, k, y, z, g):
    """`(M, h_omega, Q_gravity, r_P, T)` of the package and of the point-mass reference (compiled once)."""
    energy = _reference_energy(u, m, k)
    m_ref = jax.hessian(energy, argnums=1)(y, z)
    h_ref = jax.jacfwd(jax.grad(energy, argnums=1), argnums=0)(y, z) @ z - jax.grad(energy, argnums=0)(y, z)
    q_ref = jax.vjp(lambda yy: yy[:3] + _rotate(yy[3:], u), y)[1](m[:, None] * g)[0]
    t_ref = energy(y, z) - 0.5 * k * (y[3:] @ z[3:]) ** 2 / (y[3:] @ y[3:])
    package = (body_mass_matrix(data, y), -body_inertia_and_elastic_forces(data, y, z),
               _rigid_body.gravity_force(data, g, y), marker_position(data, 1, y), _rigid_body.kinetic_energy(data, y, z))
    return package, (m_ref, h_ref, q_ref, y[:3] + _rotate(y[3:], u[1]), t_ref)


def test_hinge_first_acceleration_is_eulers_equation():
    """A body hinged to the ground about the horizontal x axis, released at rest with its centre of mass
    level with the hinge at `(0, l, 0)`: `omega'dot = (-m g l / J_xx, 0, 0)` (Euler's equation about the fixed
    axis; gravity's moment about the hinge is `(0, l, 0) x (0, 0, -m g)`)."""
    l, m = 0.4, 2.0
    j_origin = np.diag([0.05, 0.03, 0.06]) + m * l**2 * np.diag([1.0, 0.0, 1.0])  # parallel axes, s = (0, m l, 0)
    data = fj.spatial_rigid_body_data(m, [0.0, m * l, 0.0], j_origin, [[0.0, 0.0, 0.0]])
    scene = fj.Scene(bodies=(fj.Body("link", data),), constraints=(fj.SpatialRevolute(0, 0, (1.0, 0.0, 0.0)),),
                     forces=(fj.Gravity((0.0, 0.0, -G)),))
    positions = np.array([0, 0, 0, 1.0, 0, 0, 0])
    partition = choose_partition(scene, 0.0, positions)
    assert partition.independent == (3, 4)  # e0 (gauge) and e1 (the hinge angle): regular at every angle
    model = MinimalModel(partition=partition, reference_dependent=jnp.asarray(positions[list(partition.dependent)]))
    omega_dot = _initial_angular_acceleration(model, scene, jnp.asarray(positions[3:5]), jnp.zeros(2))
    expected = m * G * l / j_origin[0, 0]
    np.testing.assert_allclose(omega_dot, [-expected, 0.0, 0.0], atol=ROUND_OFF * expected)


@eqx.filter_jit
def _initial_angular_acceleration(model, scene, y0, z0):
    t0 = jnp.zeros(())
    y_r, _, zdot = model.state_and_accelerations(t0, y0, z0, scene)
    # At rest gamma = 0, so the redundant accelerations are J zdot with J = dz_r/dz (paper eq. 13).
    jac = jax.jacfwd(lambda zz: model.velocities(t0, y_r, zz, scene))(z0)
    return angular_velocity(y_r[3:], jac[3:] @ zdot)  # at rest omega'dot = 2 G pddot / |p|^2


def test_zero_length_axis_and_bad_spatial_input():
    """A joint axis of zero length, planar gravity on a spatial body and an impossible inertia are clear errors."""
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialRevolute(0, 0, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialRevolute(0, 0, (1.0, 0.0, 0.0), 1, 0, axis_j=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="rotation axis"):
        fj.euler_parameters((0.0, 0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match="principal moments"):  # 1 + 1 < 3 about the centre of mass
        fj.spatial_rigid_body_data(1.0, [0.0, 0.0, 0.0], np.diag([1.0, 1.0, 3.0]), [[0.0, 0.0, 0.0]])
    data = fj.spatial_rigid_body_data(1.0, [0.0, 0.0, 0.1], np.diag([0.02, 0.02, 0.01]), [[0.0, 0.0, 0.0]])
    scene = fj.Scene(bodies=(fj.Body("top", data),), constraints=(fj.SphericalJoint(0, 0),), forces=(fj.Gravity(),))
    with pytest.raises(ValueError, match=r"needs a \(3,\) acceleration"):
        scene.applied_forces(0.0, jnp.array([0, 0, 0, 1.0, 0, 0, 0]), jnp.zeros(7))
    assert scene.coordinate_names() == ("top.R_x", "top.R_y", "top.R_z", "top.e0", "top.e1", "top.e2", "top.e3")
    planar = fj.Body("link", fj.rigid_body_data(1.0, [0.0, 0.0], 0.1, [[0.0, 0.0]]))
    mixed = fj.Scene(bodies=(fj.Body("top", data), planar), constraints=(fj.SphericalJoint(0, 0, 1, 0),))
    with pytest.raises(ValueError, match="is planar"):
        mixed.constraint_residual(0.0, jnp.zeros(10))


# --- the heavy symmetric top -----------------------------------------------------------------------
def steady_precession_rate(spin: float, tilt: float) -> float:
    """The slow steady precession rate `Omega` of the heavy symmetric top.

    With Euler angles (precession `phi`, tilt `theta`, spin `psi`) the Lagrangian is
    `L = I1/2 (theta'^2 + phi'^2 sin^2 theta) + I3/2 (psi' + phi' cos theta)^2 - m g l cos theta`, and
    `omega3 = psi' + phi' cos theta` is conserved. Its `theta` equation,
    `I1 theta'' = I1 phi'^2 sin theta cos theta - I3 omega3 phi' sin theta + m g l sin theta`, has the solution
    `theta' = 0`, `phi' = Omega` where `I1 Omega^2 cos theta - I3 omega3 Omega + m g l = 0`. The smaller root
    (the slow precession, ~ `m g l / (I3 omega3)` for a fast top) written without cancellation:
    `Omega = 2 m g l / (I3 omega3 + sqrt((I3 omega3)^2 - 4 I1 m g l cos theta))`.
    """
    b = I3 * spin
    return 2.0 * MASS * G * LENGTH / (b + np.sqrt(b * b - 4.0 * I1 * MASS * G * LENGTH * np.cos(tilt)))


def _top_problem(body_omega) -> fj.Problem:
    """The top tilted by `TILT` about the inertial x axis (its axis then points to `(0, -sin, cos)`), with
    body-frame angular velocity `body_omega`; gravity along `-z`, the tip held at the origin."""
    data = fj.spatial_rigid_body_data(MASS, [0.0, 0.0, MASS * LENGTH], np.diag([I1, I1, I3]), [[0.0, 0.0, 0.0]])
    scene = fj.Scene(bodies=(fj.Body("top", data),), constraints=(fj.SphericalJoint(0, 0),),
                     forces=(fj.Gravity((0.0, 0.0, -G)),))
    p0 = fj.euler_parameters((1.0, 0.0, 0.0), TILT)
    rates = np.asarray(fj.euler_parameter_rates(p0, body_omega))
    return fj.Problem(scene, T1, positions=np.concatenate([np.zeros(3), p0]), velocities=rates,
                      objective=fj.KineticEnergy())


@eqx.filter_jit
def _top_invariants(problem, positions, velocities):
    """Along a trajectory: the symmetry axis `A e3`, energy `T + V`, angular momentum about the tip
    (components along the vertical and along the symmetry axis) and `|p|^2`."""
    scene = problem.scene
    data = scene.bodies[0].data

    def one(y, z):
        axis = rotation_matrix(y[3:7])[:, 2]
        _, h = _rigid_body.momenta(data, y, z)
        energy = scene.kinetic_energy(y, z) + scene.potential_energy(jnp.zeros(()), y)
        return axis, energy, h[2], h @ axis, y[3:7] @ y[3:7]

    return jax.vmap(one)(positions, velocities)


@pytest.fixture(scope="module")
def tops():
    """Two runs of one compiled program: steady precession, and a nutating top (released with spin only)."""
    omega = steady_precession_rate(SPIN, TILT)
    steady = _top_problem([0.0, omega * np.sin(TILT), SPIN])
    nutating = _top_problem([0.0, 0.0, SPIN])
    ts = jnp.linspace(0.0, T1, 41)
    out = {}
    for name, problem in (("steady", steady), ("nutating", nutating)):
        traj = fj.simulate(problem, ts=ts, rtol=RTOL, atol=ATOL)
        out[name] = (np.asarray(traj.ts), *(np.asarray(a) for a in _top_invariants(problem, traj.positions, traj.velocities)))
    return omega, out


def test_heavy_top_steady_precession_rate(tops):
    """Started on the steady precession, the axis keeps its tilt and turns about the vertical at the analytic
    rate `Omega` (checked as the azimuth `phi(t) - phi(0) = Omega t` at every output time over ~0.6 turn)."""
    omega, out = tops
    ts, axis = out["steady"][0], out["steady"][1]
    np.testing.assert_allclose(np.arccos(np.clip(axis[:, 2], -1, 1)), TILT, atol=SOLVER_DRIFT)
    azimuth = np.unwrap(np.arctan2(axis[:, 0], -axis[:, 1]))  # 0 at the start, where the axis is (0, -sin, cos)
    np.testing.assert_allclose(azimuth - azimuth[0], omega * ts, atol=SOLVER_DRIFT * omega * T1)
    assert omega * T1 > 3.0  # the check spans a large angle, so a rate error of 1e-7 would show


@pytest.mark.parametrize("run", ["steady", "nutating"])
def test_heavy_top_conserves_energy_and_angular_momenta(tops, run):
    """`T + V`, the angular momentum about the vertical through the tip and its component along the
    symmetry axis (`I3 omega3`) stay constant; `|p|` too (the gauge direction does not drift)."""
    _, out = tops
    _, axis, energy, h_vertical, h_axis, norm2 = out[run]
    if run == "nutating":  # the nutation is a real motion: the tilt swings by a large angle
        assert np.ptp(np.arccos(np.clip(axis[:, 2], -1, 1))) > 1e-2
    for name, value, scale in (("energy", energy, abs(energy[0])), ("H_vertical", h_vertical, I3 * SPIN),
                               ("H_axis", h_axis, I3 * SPIN), ("|p|^2", norm2, 1.0)):
        assert np.max(np.abs(value - value[0])) <= SOLVER_DRIFT * scale, f"{run}: {name} drifts by {np.ptp(value)}"


# --- a driven spatial crank ------------------------------------------------------------------------
DRIVE_AXIS = np.array([1.0, 2.0, 2.0]) / 3.0
DRIVE_SPEED = 4.0 * np.pi


def _axis_rotation(n, angle):
    """Rodrigues' formula `I + sin(a) n~ + (1 - cos(a)) n~^2` (independent of the Euler parameters)."""
    k = np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def _driven_guess(t, y, scene):
    """Closed-form dependent coordinates (crank R, p; bob R) at the prescribed angle: Newton from the initial
    configuration does not converge beyond about a quarter turn (at half a turn its Jacobian is singular there)."""
    del y
    half = 0.5 * scene.constraints[1].angle(t)
    p = jnp.concatenate([jnp.cos(half)[None], jnp.sin(half) * scene.constraints[1].axis])
    return jnp.concatenate([jnp.zeros(3), p, rotation_matrix(p) @ scene.bodies[0].data.marker_positions[1]])


@eqx.filter_jit
def _driven_states(model, scene, ts, y, z):
    return jax.vmap(lambda t: model.state(t, y, z, scene))(ts)


def test_angle_driver_turns_a_hinged_body_through_full_turns():
    """A crank hinged about a skew ground axis and driven at constant speed, with a bob hanging from its pin:
    with the driver and the normalisation all its Euler parameters are dependent, regular at every angle, and
    its rotation and angular velocity are the prescribed ones (Rodrigues' formula) through two full turns."""
    a = 0.1
    s_crank = np.array([0.5 * a / 2, 0.0, 0.0])
    crank = fj.spatial_rigid_body_data(0.5, s_crank, np.diag([1e-4, 1e-3, 1e-3]) + (
        (s_crank @ s_crank) * np.eye(3) - np.outer(s_crank, s_crank)) / 0.5, [[0.0, 0.0, 0.0], [a, 0.0, 0.0]])
    bob = fj.spatial_rigid_body_data(0.3, [0.0, 0.0, -0.06], np.diag([0.013, 0.013, 1e-4]), [[0.0, 0.0, 0.0]])
    law = fj.ConstantSpeedLaw(speed=DRIVE_SPEED)
    scene = fj.Scene(bodies=(fj.Body("crank", crank), fj.Body("bob", bob)),
                     constraints=(fj.SpatialRevolute(0, 0, DRIVE_AXIS), fj.SpatialAngleDriver(0, DRIVE_AXIS, law),
                                  fj.EulerNormalisation(0), fj.SphericalJoint(1, 0, 0, 1)),
                     forces=(fj.Gravity((0.0, 0.0, -G)),))
    positions = np.concatenate([np.zeros(3), [1.0, 0.0, 0.0, 0.0], [a, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    partition = choose_partition(scene, 0.0, positions)
    assert partition.dependent == tuple(range(10))  # the crank's 7 coordinates and the bob's R
    model = MinimalModel(partition=partition, reference_dependent=jnp.asarray(positions[:10]),
                            dependent_guess=_driven_guess)
    ts = jnp.linspace(0.0, 1.0, 9)  # every eighth of a second: quarter turns, through 0, pi, 2 pi, ...
    y_r, z_r = _driven_states(model, scene, ts, jnp.asarray(positions[10:]), jnp.zeros(4))
    for k, t in enumerate(np.asarray(ts)):
        a_k = np.asarray(rotation_matrix(y_r[k, 3:7]))
        np.testing.assert_allclose(a_k, _axis_rotation(DRIVE_AXIS, DRIVE_SPEED * t), atol=ROUND_OFF)
        omega = np.asarray(angular_velocity(y_r[k, 3:7], z_r[k, 3:7]))
        np.testing.assert_allclose(a_k @ omega, DRIVE_SPEED * DRIVE_AXIS, atol=ROUND_OFF * DRIVE_SPEED)
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialAngleDriver(0, (0.0, 0.0, 0.0), law)
