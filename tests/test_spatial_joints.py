"""Spatial joints and the translation driver (issue 26): residual, Jacobian and rank at generic configurations, and
bad input.

Each joint joins body `i` to body `j` (rigid-rigid, flexible-flexible) or to the ground, at a configuration built
here from the joint's geometry (random poses, markers and axes; body `i` placed so that the joint holds). The check
of the Jacobian `C = dc/dy_r` (`jax.jacfwd` of the residual, what the model uses) is by the joint's kinematics,
written independently of the joint's equations: the velocities that the joint allows (the `6 - n_c` relative
motions, e.g. the turn about and the slide along a cylindrical joint's axis; a common rigid motion of both bodies;
the gauge `pdot ~ p` of each body's Euler parameters) lie in the null space of `C`, they span a space of dimension
`n_r - n_c`, and `C` has rank `n_c`. Together: the null space of `C` is exactly the span of the allowed motions, so
`C` is right to first order (a wrong sign, a missing or an extra equation fails).

A flexible body's marker moves and turns, to first order in `q` at `q = 0`, as a rigid body translated by
`A Phi_P qdot` at the marker and turned by `A Psi_P qdot`: so `C qdot_k` equals `C` times that rigid velocity.

One scene per variant (every joint on its own bodies), each compiled once (slow set); bad input in the default suite.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._spatial._euler_parameters import quaternion_product

# The residuals and the products `C z` are a few dozen flops on numbers of size 1: round-off ~1e-15 each.
ROUND_OFF = 1e-12
# Rank: a generic configuration keeps the singular values of `C` of order 0.1-1; a missing equation or a
# repeated one gives a singular value of round-off size (~1e-16 relative). 1e-8 separates the two by far.
RANK_TOL = 1e-8

N_Q = 2
RNG = np.random.default_rng(26)


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _rotation(p):
    """`A(p)` from the vector form `u + 2 e0 (e x u) + 2 e x (e x u)` (independent of the package's matrix)."""
    e0, e = p[0], p[1:]
    return np.stack([u + 2 * e0 * np.cross(e, u) + 2 * np.cross(e, np.cross(e, u)) for u in np.eye(3)], axis=1)


def _quaternion(a):
    """Euler parameters of a rotation matrix (Shepperd's method, largest pivot)."""
    tr = np.trace(a)
    k = np.argmax([tr, a[0, 0], a[1, 1], a[2, 2]])
    if k == 0:
        e0 = 0.5 * np.sqrt(1 + tr)
        return np.array([e0, a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1]]) / np.array([1, 4 * e0, 4 * e0,
                                                                                             4 * e0])
    i = k - 1
    j, m = (i + 1) % 3, (i + 2) % 3
    e = np.zeros(3)
    e[i] = 0.5 * np.sqrt(1 + 2 * a[i, i] - tr)
    e[j] = (a[j, i] + a[i, j]) / (4 * e[i])
    e[m] = (a[m, i] + a[i, m]) / (4 * e[i])
    return np.concatenate([[(a[m, j] - a[j, m]) / (4 * e[i])], e])


def _align(a, b):
    """Euler parameters of a rotation taking unit `a` to unit `b`."""
    axis = np.cross(a, b)
    return fj.euler_parameters(axis, np.arccos(np.clip(a @ b, -1, 1))) if np.linalg.norm(axis) > 1e-12 else np.array(
        [1.0, 0, 0, 0])


def _random_pose():
    return RNG.normal(size=3), fj.euler_parameters(RNG.normal(size=3), RNG.uniform(0.5, 2.5))


def _perpendicular(a):
    return _unit(np.cross(a, RNG.normal(size=3)))


def _rigid_data():
    return fj.spatial_rigid_body_data(1.0, [0.1, -0.2, 0.05], np.diag([1.0, 1.2, 1.5]), RNG.normal(size=(2, 3)))


def _flexible_data():
    nodes = RNG.normal(size=(4, 3))
    return fj.spatial_flexible_body_data(RNG.uniform(0.5, 1.5, 4), nodes, 0.3 * RNG.normal(size=(4, 3, N_Q)),
                                         np.diag([40.0, 90.0]), markers=(0, 1),
                                         marker_rotations=0.5 * RNG.normal(size=(2, 3, N_Q)))


def _data_makers():
    """One rigid and one flexible body data for all bodies, each built once when first asked for (building flexible
    data eagerly costs ~0.3 s each; the configurations, axes and joint points are random per joint anyway)."""
    return functools.cache(_rigid_data), functools.cache(_flexible_data)


# --- each joint: its construction at a generic configuration and the relative motions it allows ---------------
# A builder takes (body_i, body_j, u_P, u_Q, A_j, r_Q) (r_Q the inertial joint point of body j or the ground point)
# and returns (joints, A_i, r_P, motions): the joint(s), body i's rotation and marker position, and the allowed
# relative motions of body i as (omega, x, v), the velocity field `v + omega x (y - x)` with body j at rest.
def _universal(bi, bj, a_j, r_q):
    arm_i, arm_j = _unit(RNG.normal(size=3)), _unit(RNG.normal(size=3))
    w = a_j @ arm_j
    target = _perpendicular(w)
    p_i = quaternion_product(fj.euler_parameters(target, RNG.uniform(0, 6)), _align(arm_i, target))
    joint = fj.SpatialUniversal(bi, 0, arm_i, bj, 0, arm_j if bj >= 0 else w, point=r_q)
    return (joint,), p_i, r_q, [(target, r_q, np.zeros(3)), (w, r_q, np.zeros(3))]


def _cylinder_pose(axis_i, a):
    return quaternion_product(fj.euler_parameters(a, RNG.uniform(0, 6)), _align(axis_i, a))


def _cylindrical(bi, bj, a_j, r_q):
    axis_i, axis_j = _unit(RNG.normal(size=3)), _unit(RNG.normal(size=3))
    a = a_j @ axis_j
    joint = fj.SpatialCylindrical(bi, 0, axis_i, bj, 0, axis_j if bj >= 0 else a, point=r_q)
    return (joint,), _cylinder_pose(axis_i, a), r_q + RNG.normal() * a, [(a, r_q, np.zeros(3)), (np.zeros(3), r_q, a)]


def _prismatic(bi, bj, a_j, r_q):
    axis_i, axis_j = _unit(RNG.normal(size=3)), _unit(RNG.normal(size=3))
    normal_i, normal_j = _perpendicular(axis_i), _perpendicular(axis_j)
    f_i = np.stack([axis_i, normal_i, np.cross(axis_i, normal_i)], axis=1)
    f_j = a_j @ np.stack([axis_j, normal_j, np.cross(axis_j, normal_j)], axis=1)
    a = f_j[:, 0]
    if bj >= 0:
        joint = fj.SpatialPrismatic(bi, 0, axis_i, bj, 0, axis_j, normal_i=normal_i, normal_j=normal_j)
    else:
        joint = fj.SpatialPrismatic(bi, 0, axis_i, axis_j=a, normal_i=normal_i, normal_j=f_j[:, 1], point=r_q)
    return (joint,), _quaternion(f_j @ f_i.T), r_q + RNG.normal() * a, [(np.zeros(3), r_q, a)]


def _rigid(bi, bj, a_j, r_q):
    c = fj.euler_parameters(RNG.normal(size=3), RNG.uniform(0.5, 2.5))
    if bj >= 0:
        joint = fj.SpatialRigidAttachment(bi, 0, bj, 0, rotation=c)
    else:  # the matrix form of the rotation
        joint = fj.SpatialRigidAttachment(bi, 0, rotation=_rotation(c), point=r_q)
    return (joint,), _quaternion(a_j @ _rotation(c)), r_q, []


LAW = fj.HarmonicLaw(0.3, 0.7, phase=0.4, offset=0.1)
T_CHECK = 0.37


def _driven(bi, bj, a_j, r_q):
    axis_i, axis_j = _unit(RNG.normal(size=3)), _unit(RNG.normal(size=3))
    a = a_j @ axis_j
    axis = axis_j if bj >= 0 else a
    joints = (fj.SpatialCylindrical(bi, 0, axis_i, bj, 0, axis, point=r_q),
              fj.SpatialTranslationDriver(bi, 0, axis, LAW, bj, 0, point=r_q))
    return joints, _cylinder_pose(axis_i, a), r_q + float(LAW(T_CHECK)) * a, [(a, r_q, np.zeros(3))]


BUILDERS = {"universal": _universal, "cylindrical": _cylindrical, "prismatic": _prismatic, "rigid attachment": _rigid,
            "cylindrical + translation driver": _driven}
VARIANTS = ("rigid pair", "ground", "flexible pair")


def _rates(p, omega):
    """`pdot = 1/2 G(p)^T A^T omega` for unit `p` and inertial angular velocity `omega`."""
    return np.asarray(fj.euler_parameter_rates(p, _rotation(p).T @ omega))


@functools.cache
def _assembled(variant: str):
    """One scene holding every joint in one variant on its own bodies; its configuration; per joint the rows of its
    equations, the coordinates of its bodies and the allowed velocities (full redundant vectors). Compiled once per
    variant (the rigid pairs ~1-2 s; each variant's scene is a third of the work of one scene with all of them)."""
    bodies, cases = [], []
    rigid_data, flexible_data = _data_makers()
    for name in BUILDERS:
        data = flexible_data if variant == "flexible pair" else rigid_data
        bj = -1
        if variant != "ground":
            bj = len(bodies)
            bodies.append(data())
        bi = len(bodies)
        bodies.append(data())
        cases.append((name, variant, bi, bj))
    scene_bodies = tuple(fj.Body(f"b{k}", d) for k, d in enumerate(bodies))
    sizes = [7 + (N_Q if isinstance(d, fj.SpatialFlexibleBodyData) else 0) for d in bodies]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    y = np.zeros(offsets[-1])
    constraints, info = [], []
    for name, variant, bi, bj in cases:
        u_p = np.asarray(bodies[bi].marker_positions[0])
        if bj >= 0:
            r_j, p_j = _random_pose()
            a_j = _rotation(p_j)
            u_q = np.asarray(bodies[bj].marker_positions[0])
            r_q = r_j + a_j @ u_q
            y[offsets[bj]:offsets[bj] + 7] = np.concatenate([r_j, p_j])
        else:
            a_j, r_q = np.eye(3), RNG.normal(size=3)
        joints, p_i, r_p, motions = BUILDERS[name](bi, bj, a_j, r_q)
        a_i = _rotation(p_i)
        y[offsets[bi]:offsets[bi] + 7] = np.concatenate([r_p - a_i @ u_p, p_i])
        rows = (sum(c.n_equations for c in constraints), sum(c.n_equations for c in constraints + list(joints)))
        constraints += list(joints)
        info.append((name, variant, bi, bj, rows, motions))
    scene = fj.Scene(bodies=scene_bodies, constraints=tuple(constraints))
    residual, jacobian, c_t = _evaluate(scene, jnp.asarray(T_CHECK), jnp.asarray(y))
    return scene, y, offsets, info, np.asarray(residual), np.asarray(jacobian), np.asarray(c_t)


@eqx.filter_jit
def _evaluate(scene, t, y):
    c_t, c = jax.jacfwd(scene.constraint_residual, argnums=(0, 1))(t, y)
    return scene.constraint_residual(t, y), c, c_t


def _body_velocity(y, offsets, b, omega, x, v, flexible_mode=None, scene=None):
    """The redundant velocity of body `b` moving with the field `v + omega x (y - x)` (inertial), or, for a flexible
    body and `flexible_mode = k`, the unit modal rate `qdot_k` alone."""
    z = np.zeros_like(y)
    o = offsets[b]
    if flexible_mode is not None:
        z[o + 7 + flexible_mode] = 1.0
        return z
    r, p = y[o:o + 3], y[o + 3:o + 7]
    z[o:o + 3] = v + np.cross(omega, r - x)
    z[o + 3:o + 7] = _rates(p, omega)
    return z


def _allowed(y, offsets, bi, bj, motions):
    """The allowed velocities: relative motions of body i, common rigid motions (6), the gauges of both bodies."""
    zs = [_body_velocity(y, offsets, bi, *m) for m in motions]
    for k in range(6):
        omega, v = (np.eye(3)[k], np.zeros(3)) if k < 3 else (np.zeros(3), np.eye(3)[k - 3])
        if bj < 0:
            continue  # the ground does not move
        zs.append(_body_velocity(y, offsets, bi, omega, np.zeros(3), v) + _body_velocity(y, offsets, bj, omega,
                                                                                            np.zeros(3), v))
    for b in (bi, bj):
        if b >= 0:
            z = np.zeros_like(y)
            z[offsets[b] + 3:offsets[b] + 7] = y[offsets[b] + 3:offsets[b] + 7]
            zs.append(z)
    return np.stack(zs)


# One compile per variant, ~1-3 s CPU each: over the default suite's budget for new tests, so in the slow set.
CASES = [(name, variant) for name in BUILDERS for variant in VARIANTS]


@pytest.mark.slow
@pytest.mark.parametrize("name,variant", CASES)
def test_joint_residual_and_jacobian(name, variant):
    """At the assembled configuration the residual vanishes, `C` has full row rank, and its null space on the
    joint's bodies is spanned by the motions the joint allows (counted: `n_coordinates - n_equations`)."""
    scene, y, offsets, info, residual, jac, _ = _assembled(variant)
    (_, _, bi, bj, (r0, r1), motions), = [i for i in info if i[:2] == (name, variant)]
    c = jac[r0:r1]
    assert np.max(np.abs(residual[r0:r1])) <= ROUND_OFF, f"{name} ({variant}): residual {residual[r0:r1]}"
    columns = np.concatenate([np.arange(offsets[b], offsets[b + 1]) for b in (bi, bj) if b >= 0])
    other = np.setdiff1d(np.arange(len(y)), columns)
    assert not np.any(c[:, other]), "a joint's equations depend on its own bodies only"
    rigid_columns = np.concatenate([np.arange(offsets[b], offsets[b] + 7) for b in (bi, bj) if b >= 0])
    sv = np.linalg.svd(c[:, rigid_columns], compute_uv=False)
    assert sv[-1] > RANK_TOL * sv[0], f"{name} ({variant}): rank below {r1 - r0}, singular values {sv}"
    allowed = _allowed(y, offsets, bi, bj, motions)
    assert allowed.shape[0] == len(rigid_columns) - (r1 - r0), "the allowed motions fill the null space"
    a_sv = np.linalg.svd(allowed[:, rigid_columns], compute_uv=False)
    assert a_sv[-1] > RANK_TOL * a_sv[0], "the allowed motions are independent"
    scale = np.max(np.abs(c)) * np.max(np.abs(allowed))
    assert np.max(np.abs(allowed @ c.T)) <= ROUND_OFF * scale, f"{name} ({variant}): C z != 0 for an allowed motion"


@pytest.mark.slow
@pytest.mark.parametrize("name", list(BUILDERS))
def test_flexible_marker_moves_as_its_elastic_motion(name):
    """On flexible bodies at `q = 0`, `C e_{q_k}` = `C` times the rigid velocity that translates the marker by
    `A Phi_P e_k` and turns it by `A Psi_P e_k`, for every mode of both bodies."""
    scene, y, offsets, info, _, jac, _ = _assembled("flexible pair")
    (_, _, bi, bj, (r0, r1), _), = [i for i in info if i[:2] == (name, "flexible pair")]
    c = jac[r0:r1]
    for b in (bi, bj):
        data = scene.bodies[b].data
        o = offsets[b]
        a = _rotation(y[o + 3:o + 7])
        marker = a @ np.asarray(data.marker_positions[0]) + y[o:o + 3]
        for k in range(N_Q):
            elastic = _body_velocity(y, offsets, b, None, None, None, flexible_mode=k)
            omega = a @ np.asarray(data.marker_rotations[0, :, k])
            rigid = _body_velocity(y, offsets, b, omega, marker, a @ np.asarray(data.marker_modes[0, :, k]))
            assert np.max(np.abs(c @ (elastic - rigid))) <= ROUND_OFF * np.max(np.abs(c)), (name, b, k)
            assert np.max(np.abs(c @ elastic)) > 1e-3, "the modes do move the joint (the check can fail)"


@pytest.mark.slow
def test_translation_driver_time_derivative():
    """`dc/dt = -s'(t)` for the translation driver (the rheonomic term of the velocity constraint);
    `s' = 2 pi f A cos(2 pi f t + phase)` of the harmonic law."""
    _, _, _, info, _, _, c_t = _assembled("rigid pair")
    rate = 2 * np.pi * 0.7 * 0.3 * np.cos(2 * np.pi * 0.7 * T_CHECK + 0.4)
    for name, variant, _, _, (r0, r1), _ in info:
        want = np.zeros(r1 - r0)
        if name == "cylindrical + translation driver":
            want[-1] = -rate
        np.testing.assert_allclose(c_t[r0:r1], want, atol=ROUND_OFF, err_msg=f"{name} ({variant})")


def test_bad_joint_input_is_refused():
    """Zero-length axes, normals not at right angles to their axes, a missing arm, a non-rotation, and planar
    bodies are clear errors."""
    zero = (0.0, 0.0, 0.0)
    x, y = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    for make in (lambda: fj.SpatialUniversal(0, 0, zero, axis_j=y), lambda: fj.SpatialUniversal(0, 0, x, axis_j=zero),
                 lambda: fj.SpatialCylindrical(0, 0, zero), lambda: fj.SpatialCylindrical(0, 0, x, 1, 0, zero),
                 lambda: fj.SpatialPrismatic(0, 0, zero), lambda: fj.SpatialTranslationDriver(0, 0, zero, 0.1)):
        with pytest.raises(ValueError, match="zero length"):
            make()
    with pytest.raises(ValueError, match="needs axis_j"):
        fj.SpatialUniversal(0, 0, x)
    with pytest.raises(ValueError, match="not perpendicular"):
        fj.SpatialPrismatic(0, 0, x, normal_i=(1.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="needs normal_i and normal_j"):
        fj.SpatialPrismatic(0, 0, x, 1, 0, y)
    with pytest.raises(ValueError, match="not a rotation"):
        fj.SpatialRigidAttachment(0, 0, rotation=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="ground point"):
        fj.SpatialCylindrical(0, 0, x, point=(np.nan, 0.0, 0.0))
    spatial = fj.Body("spatial", _rigid_data())
    planar = fj.Body("planar", fj.rigid_body_data(1.0, [0.0, 0.0], 0.1, [[0.0, 0.0]]))
    for joint in (fj.SpatialUniversal(0, 0, x, 1, 0, y), fj.SpatialCylindrical(0, 0, x, 1, 0),
                  fj.SpatialPrismatic(0, 0, x, 1, 0), fj.SpatialRigidAttachment(0, 0, 1, 0),
                  fj.SpatialTranslationDriver(0, 0, x, 0.1, 1, 0)):
        scene = fj.Scene(bodies=(spatial, planar), constraints=(joint,))
        with pytest.raises(ValueError, match="is planar"):
            scene.constraint_residual(0.0, jnp.zeros(10))
    with pytest.raises(ValueError, match="not a marker"):
        fj.Scene(bodies=(spatial,), constraints=(fj.SpatialCylindrical(0, 5, x),))
