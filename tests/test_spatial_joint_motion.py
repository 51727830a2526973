"""Spatial joints in motion (issue 26), each checked by a route independent of its equations. One scene holds four
independent mechanisms (one compiled solve, 1 s of motion under gravity `g = (0, 0, -9.81)`):

- a body on an inclined **prismatic** joint to the ground falls along the axis as a point mass on a frictionless
  incline: `s(t) = s0 + v0 t + 1/2 (g . d) t^2` (the joint's reactions are at right angles to `d` or moments);
- a body with its centre of mass off the axis on a vertical **cylindrical** joint spins and falls: the reactions are
  forces through the axis at right angles to it and moments at right angles to it, so the momentum along the axis
  grows as `m g t`, the angular momentum about the axis is conserved, and so is `T + V`;
- a **universal** joint between an input shaft (a hinge about `x`) and an output shaft at the bend angle `beta`
  (held on its axis by the joint's centre and a point-on-line): the angles obey Cardan's relation
  `tan phi_1 = cos(beta) tan phi_2` (angles from the arms' initial position, the input arm in the plane of the
  shafts) and the speeds `omega_2 / omega_1 = cos(beta) / (1 - sin^2(beta) cos^2(phi_1))` (its derivative), and
  `T + V` is conserved;
- a **translation driver** on a prismatic slider: the slide is the prescribed `s(t)` and its rate `s'(t)`.

And, without a solve: two bodies welded by a **rigid attachment**, hanging from a spherical joint, have the
accelerations of the one combined rigid body (its mass, first moment and inertia computed from the union of the two
point clouds, not from the joint) at a moving state (gyroscopic terms included).

The coordinate partition is given (gauge and joint coordinates independent, the output shaft's Euler parameters
dependent with their normalisation), and Newton's method starts the output shaft from Cardan's relation (only the
branch: the checks are on the converged constraints): from the initial configuration it does not converge after a
large turn. Marked slow (two compiles, ~30-60 s on the shared machine).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._dynamics._model import MinimalModel, Partition
from ffr_jax._spatial import _rigid_body
from ffr_jax._spatial._euler_parameters import angular_velocity, quaternion_product, rotation_matrix

RTOL, ATOL = 1e-10, 1e-12
# Integrated at rtol 1e-10 / atol 1e-12 (Dopri8): each step's local error ~1e-10 of the state, the global error
# after ~100 steps ~1e-8 of the state's size; smooth functions of the state (momenta, energies, angles, the
# pose of a body), scaled by their own size, drift by that much at most. A wrong reaction (a joint that does work
# or holds the wrong direction) changes them at the 1e-2 level within this second of motion.
SOLVER_DRIFT = 1e-7
# Kinematic checks (the driver): the dependent coordinates are solved by Newton's method to 1e-13 (1 + |y_d|), the
# dependent velocities by one linear solve (round-off); the scene's coordinates are of size ~3.
NEWTON = 1e-11
G = np.array([0.0, 0.0, -9.81])
T1 = 1.0
BETA = np.pi / 6


def _cloud(seed, n=6, centre=(0.0, 0.0, 0.0), spread=(0.3, 0.2, 0.1)):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.5, 1.5, n), rng.normal(size=(n, 3)) * np.asarray(spread) + np.asarray(centre)


def _data(masses, points, markers):
    j = np.einsum("k,kij->ij", masses, np.einsum("ki,ki->k", points, points)[:, None, None] * np.eye(3)
                  - points[:, :, None] * points[:, None, :])
    return fj.spatial_rigid_body_data(masses.sum(), masses @ points, j, np.asarray(markers, dtype=float))


def _shaft(length, markers):
    """A balanced shaft along its body x axis (centre of mass on the axis at the origin)."""
    m, r = 2.0, 0.05
    return fj.spatial_rigid_body_data(m, [0.0, 0.0, 0.0], np.diag([0.5 * m * r**2, m * length**2 / 12,
                                                                    m * length**2 / 12]), markers)


# The mechanisms' geometry.
INCLINE = np.array([1.0, 0.5, -1.0]) / 1.5                 # prismatic axis (unit)
INCLINE_POINT = np.array([0.0, -2.0, 0.0])
SPIN_AXIS, SPIN_POINT = np.array([0.0, 0.0, 1.0]), np.array([2.0, 0.0, 0.0])
SHAFT_CENTRE = np.array([0.0, 2.0, 0.0])
S2 = np.array([np.cos(BETA), np.sin(BETA), 0.0])          # output shaft axis
PIVOT = np.array([-2.0, 0.0, 1.0])                         # the welded pair's (and the combined body's) pivot
WELD = fj.euler_parameters([0.3, -1.0, 0.5], 1.1)          # the lower body's orientation in the upper's frame
DRIVE_AXIS, DRIVE_POINT = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0), np.array([3.0, 3.0, 0.0])
LAW = fj.HarmonicLaw(0.2, 1.3, phase=0.3, offset=0.05)


# Independent coordinates (per body, offsets 0, 7, 14, 21, 28): the slider's gauge e0 and R_x (the slide), the
# piston's e0, e3 (gauge and spin about z) and R_z, the input shaft's e0, e1 (gauge and angle), none of the output
# shaft, the driven body's gauge e0. The joints' other Euler-parameter equations are then linear near zero.
INDEPENDENT = (0, 3, 9, 10, 13, 17, 18, 31)


def _pose_rates(pose, motion):
    """Redundant velocities of a body at `pose = (R, p)` moving with the inertial field `v + omega x (y - x)`."""
    (r, p), (omega, v, x) = pose, motion
    rdot = v + (np.cross(omega, r - x) if x is not None else 0.0)
    return np.concatenate([rdot, np.asarray(fj.euler_parameter_rates(p, _rotation(p).T @ omega))])


def _rotation(p):
    return np.asarray(rotation_matrix(jnp.asarray(p)))


def _scene_and_state():
    m0, c0 = _cloud(1, centre=(0.1, 0.05, -0.1))
    m1, c1 = _cloud(2, centre=(0.2, -0.1, 0.3))
    bodies = (fj.Body("slider", _data(m0, c0, [[0.0, 0.0, 0.0]])),
              fj.Body("piston", _data(m1, c1, [[0.0, 0.0, 0.0]])),
              fj.Body("input", _shaft(1.0, [[0.0, 0.0, 0.0]])),
              fj.Body("output", _shaft(1.0, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])),
              fj.Body("driven", _data(m0, c0, [[0.0, 0.0, 0.0]])))
    constraints = (
        fj.SpatialPrismatic(0, 0, INCLINE, point=INCLINE_POINT),
        fj.SpatialCylindrical(1, 0, SPIN_AXIS, point=SPIN_POINT),
        fj.SpatialRevolute(2, 0, (1.0, 0.0, 0.0), point=SHAFT_CENTRE),
        fj.SpatialUniversal(2, 0, (0.0, 1.0, 0.0), 3, 0, (0.0, 0.0, 1.0)),
        fj.SpatialPointOnLine(3, 1, SHAFT_CENTRE, S2),
        fj.EulerNormalisation(3),
        fj.SpatialPrismatic(4, 0, DRIVE_AXIS, point=DRIVE_POINT),
        fj.SpatialTranslationDriver(4, 0, DRIVE_AXIS, LAW, point=DRIVE_POINT),
    )
    scene = fj.Scene(bodies=bodies, constraints=constraints, forces=(fj.Gravity(tuple(G)),))
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    poses = [(INCLINE_POINT + 0.3 * INCLINE, identity), (SPIN_POINT + [0.0, 0.0, 0.5], identity),
             (SHAFT_CENTRE, identity), (SHAFT_CENTRE, fj.euler_parameters((0.0, 0.0, 1.0), BETA)),
             (DRIVE_POINT + float(LAW(0.0)) * DRIVE_AXIS, identity)]
    positions = np.concatenate([np.concatenate(pose) for pose in poses])
    # The slider slides, the piston spins about the axis through SPIN_POINT and rises, the input shaft turns (the
    # output's velocities follow from the constraints), the driven body at s'(0).
    motions = [(np.zeros(3), 0.5 * INCLINE, None), (4.0 * SPIN_AXIS, 1.0 * SPIN_AXIS, SPIN_POINT),
               (3.0 * np.array([1.0, 0.0, 0.0]), np.zeros(3), SHAFT_CENTRE), (np.zeros(3), np.zeros(3), None),
               (np.zeros(3), 2 * np.pi * 1.3 * 0.2 * np.cos(0.3) * DRIVE_AXIS, None)]
    velocities = np.concatenate([_pose_rates(pose, m) for pose, m in zip(poses, motions)])
    partition = Partition(independent=INDEPENDENT, dependent=tuple(i for i in range(35) if i not in INDEPENDENT))
    return scene, positions, velocities[list(INDEPENDENT)], partition


def _cardan_guess(t, y, scene, partition, reference):
    """Newton's starting point: the initial dependent coordinates, the output shaft turned by Cardan's angle."""
    del t, scene
    y_r = jnp.zeros(35, y.dtype).at[jnp.asarray(partition.independent)].set(y)
    y_r = y_r.at[jnp.asarray(partition.dependent)].set(reference)
    phi_1 = 2.0 * jnp.arctan2(y_r[18], y_r[17])  # the input shaft's (e0, e1), a turn about x
    phi_2 = jnp.arctan2(jnp.sin(phi_1), np.cos(BETA) * jnp.cos(phi_1))
    half = 0.5 * phi_2
    q = jnp.concatenate([jnp.cos(half)[None], jnp.sin(half) * jnp.asarray(S2)])
    b = jnp.asarray(fj.euler_parameters((0.0, 0.0, 1.0), BETA))
    p_out = jnp.concatenate([(q[0] * b[0] - q[1:] @ b[1:])[None], q[0] * b[1:] + b[0] * q[1:] + jnp.cross(q[1:], b[1:])])
    return y_r.at[24:28].set(p_out)[jnp.asarray(partition.dependent)]


@eqx.filter_jit
def _observables(scene, ts, positions, velocities):
    def one(t, y, z):
        out = {}
        for b in range(len(scene.bodies)):
            data = scene.bodies[b].data
            y_b, z_b = scene.body_coordinates(b, y), scene.body_coordinates(b, z)
            out[f"T{b}"] = _rigid_body.kinetic_energy(data, y_b, z_b)
            out[f"V{b}"] = _rigid_body.gravity_potential(data, jnp.asarray(G), y_b)
            out[f"L{b}"], out[f"H{b}"] = _rigid_body.momenta(data, y_b, z_b)
            out[f"A{b}"] = rotation_matrix(y_b[3:7])
            out[f"omega{b}"] = rotation_matrix(y_b[3:7]) @ angular_velocity(y_b[3:7], z_b[3:7])
            out[f"r{b}"] = scene.marker_position(b, 0, y)
            out[f"v{b}"] = jax.jvp(lambda yy: scene.marker_position(b, 0, yy), (y,), (z,))[1]
        out["closure"] = jnp.max(jnp.abs(scene.constraint_residual(t, y)))
        return out

    return jax.vmap(one)(ts, positions, velocities)


@pytest.fixture(scope="module")
def motion():
    scene, positions, velocities, partition = _scene_and_state()
    reference = jnp.asarray(positions[list(partition.dependent)])
    guess = functools.partial(_cardan_guess, partition=partition, reference=reference)
    problem = fj.Problem(scene, T1, positions=positions, velocities=velocities, partition=partition,
                         dependent_guess=guess, objective=fj.KineticEnergy())
    ts = jnp.linspace(0.0, T1, 41)
    traj = fj.simulate(problem, ts=ts, rtol=RTOL, atol=ATOL)
    obs = _observables(scene, traj.ts, traj.positions, traj.velocities)
    return scene, np.asarray(traj.ts), {k: np.asarray(v) for k, v in obs.items()}


@pytest.mark.slow
def test_joints_stay_closed(motion):
    _, _, obs = motion
    assert np.max(obs["closure"]) <= NEWTON, f"constraint residual {np.max(obs['closure'])}"


@pytest.mark.slow
def test_prismatic_body_falls_along_its_axis(motion):
    """Slide `d . (r_P - point) = s0 + v0 t + 1/2 (g . d) t^2`; the body does not turn."""
    _, ts, obs = motion
    s = (obs["r0"] - INCLINE_POINT) @ INCLINE
    want = 0.3 + 0.5 * ts + 0.5 * (G @ INCLINE) * ts**2
    assert np.max(np.abs(s - want)) <= SOLVER_DRIFT * np.max(np.abs(want)), f"slide error {np.max(np.abs(s - want))}"
    off_axis = (obs["r0"] - INCLINE_POINT) - s[:, None] * INCLINE
    assert np.max(np.abs(off_axis)) <= NEWTON
    assert np.max(np.abs(obs["A0"] - np.eye(3))) <= NEWTON, "the prismatic joint holds the orientation"


@pytest.mark.slow
def test_cylindrical_body_spins_and_falls_freely(motion):
    """`a . L = a . L(0) + m (g . a) t`, `a . H_x` (about a point of the axis) constant, `T + V` constant; the body
    turns through a large angle and its centre of mass is off the axis (so the reactions are at work)."""
    scene, ts, obs = motion
    m = float(scene.bodies[1].data.mass)
    l_axis = obs["L1"] @ SPIN_AXIS
    want = l_axis[0] + m * (G @ SPIN_AXIS) * ts
    assert np.max(np.abs(l_axis - want)) <= SOLVER_DRIFT * m * 9.81 * T1
    h_axis = (obs["H1"] - np.cross(SPIN_POINT, obs["L1"])) @ SPIN_AXIS
    energy = obs["T1"] + obs["V1"]
    assert np.ptp(h_axis) <= SOLVER_DRIFT * np.max(np.abs(h_axis)), f"H_axis drifts by {np.ptp(h_axis)}"
    assert np.ptp(energy) <= SOLVER_DRIFT * np.max(np.abs(obs["T1"])), f"energy drifts by {np.ptp(energy)}"
    assert np.min(obs["A1"][:, 0, 0]) < 0.0, "the body turned by more than 90 degrees"
    assert np.max(np.abs(obs["omega1"][:, :2])) <= NEWTON, "it turns about the axis only"


@pytest.mark.slow
def test_universal_joint_follows_cardan(motion):
    """`tan phi_1 = cos(beta) tan phi_2`, written `sin phi_1 cos phi_2 = cos(beta) cos phi_1 sin phi_2` (bounded),
    the speed ratio `omega_2 / omega_1 = cos(beta) / (1 - sin^2(beta) cos^2(phi_1))`, and `T + V` of the shafts."""
    _, _, obs = motion
    arm_1 = obs["A2"] @ np.array([0.0, 1.0, 0.0])
    arm_2 = obs["A3"] @ np.array([0.0, 0.0, 1.0])
    phi_1 = np.unwrap(np.arctan2(arm_1[:, 2], arm_1[:, 1]))
    phi_2 = np.unwrap(np.arctan2(arm_2 @ np.cross(S2, [0.0, 0.0, 1.0]), arm_2[:, 2]))
    assert np.ptp(phi_1) > 2.0, "the shafts turn by a large angle"
    np.testing.assert_allclose(np.sin(phi_1) * np.cos(phi_2), np.cos(BETA) * np.cos(phi_1) * np.sin(phi_2),
                               atol=NEWTON)
    w1, w2 = obs["omega2"] @ np.array([1.0, 0.0, 0.0]), obs["omega3"] @ S2
    np.testing.assert_allclose(w2 / w1, np.cos(BETA) / (1 - np.sin(BETA) ** 2 * np.cos(phi_1) ** 2), rtol=NEWTON)
    np.testing.assert_allclose(obs["omega3"], w2[:, None] * S2, atol=NEWTON * np.max(np.abs(w2)))
    assert np.ptp(w2 / w1) > 0.1, "the speed ratio varies (the check can see a wrong joint)"
    energy = obs["T2"] + obs["T3"] + obs["V2"] + obs["V3"]
    assert np.ptp(energy) <= SOLVER_DRIFT * np.max(np.abs(energy)), f"energy drifts by {np.ptp(energy)}"


@pytest.mark.slow
def test_translation_driver_prescribes_the_slide(motion):
    """`d . (r_P - point) = s(t)` and `d . rdot_P = s'(t)` of the harmonic law."""
    _, ts, obs = motion
    s = (obs["r4"] - DRIVE_POINT) @ DRIVE_AXIS
    np.testing.assert_allclose(s, 0.05 + 0.2 * np.sin(2 * np.pi * 1.3 * ts + 0.3), atol=NEWTON)
    rate = 2 * np.pi * 1.3 * 0.2 * np.cos(2 * np.pi * 1.3 * ts + 0.3)
    np.testing.assert_allclose(obs["v4"] @ DRIVE_AXIS, rate, atol=NEWTON * np.max(np.abs(rate)))
    np.testing.assert_allclose(obs["v4"], (obs["v4"] @ DRIVE_AXIS)[:, None] * DRIVE_AXIS, atol=NEWTON)


# --- the rigid attachment: the welded pair accelerates as the combined body ----------------------------------------
@eqx.filter_jit
def _accelerations(model, scene, y, z):
    return model.state_and_accelerations(jnp.zeros(()), y, z, scene)[2]


@pytest.mark.slow
def test_rigid_attachment_accelerates_as_the_combined_body():
    """The upper body of the welded pair and the combined body, in the same moving state, have the same Euler
    parameter accelerations (to round-off of the 21 x 21 solves: 1e-10 of their size)."""
    m4, c4 = _cloud(4, centre=(0.0, 0.0, -0.3))
    m5, c5 = _cloud(5, centre=(0.1, 0.2, -0.2))
    attach_4, attach_5 = np.array([0.1, -0.1, -0.5]), np.array([-0.2, 0.1, 0.1])
    c_weld = _rotation(WELD)
    origin_5 = attach_4 - c_weld @ attach_5  # the lower body's origin in the upper body's frame
    combined = _data(np.concatenate([m4, m5]), np.concatenate([c4, origin_5 + c5 @ c_weld.T]), [[0.0, 0.0, 0.0]])
    scene = fj.Scene(bodies=(fj.Body("upper", _data(m4, c4, [[0.0, 0.0, 0.0], attach_4])),
                             fj.Body("lower", _data(m5, c5, [attach_5])), fj.Body("combined", combined)),
                     constraints=(fj.SphericalJoint(0, 0, point=PIVOT), fj.SpatialRigidAttachment(1, 0, 0, 1, rotation=WELD),
                                  fj.SphericalJoint(2, 0, point=PIVOT)),
                     forces=(fj.Gravity(tuple(G)),))
    p_hang = fj.euler_parameters([1.0, 2.0, 0.5], 0.8)
    p_lower = quaternion_product(p_hang, WELD)
    r_lower = PIVOT + _rotation(p_hang) @ attach_4 - _rotation(p_lower) @ attach_5
    poses = [(PIVOT, p_hang), (r_lower, p_lower), (PIVOT, p_hang)]
    omega = np.array([1.5, -2.0, 0.7])  # inertial, of all three bodies
    positions = np.concatenate([np.concatenate(pose) for pose in poses])
    velocities = np.concatenate([_pose_rates(pose, (omega, np.zeros(3), PIVOT)) for pose in poses])
    independent = (3, 4, 5, 6, 10, 17, 18, 19, 20)  # both bodies' Euler parameters, the lower body's gauge e0
    partition = Partition(independent=independent, dependent=tuple(i for i in range(21) if i not in independent))
    model = MinimalModel(partition=partition, reference_dependent=jnp.asarray(positions[list(partition.dependent)]))
    zdot = np.asarray(_accelerations(model, scene, jnp.asarray(positions[list(independent)]),
                                     jnp.asarray(velocities[list(independent)])))
    upper, welded = zdot[:4], zdot[5:]
    assert np.max(np.abs(upper)) > 1.0, "a sizeable acceleration (gravity and gyroscopic terms)"
    np.testing.assert_allclose(upper, welded, atol=1e-10 * np.max(np.abs(upper)))
