"""Spatial force elements (issue 26): the spring–damper and the applied force and torque.

Slow (one small compile, ~3 s): each generalized force, written out in the package, against the virtual work computed
here by automatic differentiation of the marker's position and frame, on a rigid body (Euler parameters off the
unit sphere) and on a flexible one; the spring's force at rest is `-dV/dy` of its potential, and the damper's power
is `-c l'^2`. Default: bad input only (no compile).

Slow (one compiled solve, reused for a second scene of the same structure, ~30-60 s): energy balances along a motion under
gravity. A rigid body hangs from the ground by a spring–damper and carries a flexible body on a second one: without
damping `T + V` (gravity, springs, strain) is conserved; with damping it falls by exactly the dissipated
`int c l'^2 dt` (the problem's objective, integrated with the motion). A free rigid body driven by a harmonic force
and torque: the work `int (F . rdot_P + tau . omega) dt` equals the change of `T + V_gravity`, and the momentum
changes by `int F dt + m g t`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._spatial import _flexible_body, _rigid_body
from ffr_jax._spatial._euler_parameters import angular_velocity, rotation_matrix
from ffr_jax._spatial._marker_load import marker_load

# A few dozen flops on numbers of size 1 on both sides: round-off.
ROUND_OFF = 1e-12
N_Q = 2


def _rigid_data(seed, n_markers=2):
    rng = np.random.default_rng(seed)
    m, u = rng.uniform(0.5, 1.5, 6), rng.normal(size=(6, 3)) * np.array([0.3, 0.2, 0.1])
    j = np.einsum("k,kij->ij", m, np.einsum("ki,ki->k", u, u)[:, None, None] * np.eye(3) - u[:, :, None] * u[:, None, :])
    return fj.spatial_rigid_body_data(m.sum(), m @ u, j, rng.normal(size=(n_markers, 3)) * 0.3)


def _flexible_data(seed):
    rng = np.random.default_rng(seed)
    return fj.spatial_flexible_body_data(rng.uniform(0.5, 1.5, 5), rng.normal(size=(5, 3)) * 0.3,
                                         0.1 * rng.normal(size=(5, 3, N_Q)), np.diag([40.0, 90.0]), markers=(0, 1),
                                         marker_rotations=0.5 * rng.normal(size=(2, 3, N_Q)))


def _frame(scene, b, marker, y):
    """The marker's frame `A (I + (Psi_P q)~)` (rigid: `A`), built here from the body data."""
    data = scene.bodies[b].data
    y_b = scene.body_coordinates(b, y)
    a = rotation_matrix(y_b[3:7])
    if isinstance(data, fj.SpatialFlexibleBodyData):
        theta = data.marker_rotations[marker] @ y_b[7:]
        a = a @ (jnp.eye(3) + jnp.cross(jnp.eye(3), theta))  # (I + theta~) with columns e_k + theta x e_k
    return a


@jax.jit
def _virtual_work_check(scene, y, dy, z):
    """`(Q . dy, F . dr_P + tau . dphi)` of the applied loads (and of their forces alone) (force 1 on body 0 marker 1, force 2 on body 1 marker 0);
    the spring's `(Q(z=0), -dV/dy)`; the damper's `(Q(z) - Q(0)) . z` and `-c l'^2`."""
    t = jnp.asarray(0.4)
    out = {}
    for k, force in enumerate(scene.forces[:2]):
        q = force.generalized_force(t, y, z, scene)
        f, tau = force.loads(t)
        dr = jax.jvp(lambda yy: scene.marker_position(force.body, force.marker, yy), (y,), (dy,))[1]
        a, da = jax.jvp(lambda yy: _frame(scene, force.body, force.marker, yy), (y,), (dy,))
        w = da @ a.T  # the virtual rotation dphi~ (exact where the frame is orthonormal: rigid, or q = 0)
        dphi = jnp.stack([w[2, 1], w[0, 2], w[1, 0]])
        out[f"load {k}"] = (q @ dy, f @ dr + tau @ dphi)
        data, y_b = scene.bodies[force.body].data, scene.body_coordinates(force.body, y)
        q_force = scene.scatter(force.body, marker_load(data, force.marker, y_b, f, jnp.zeros(3)))
        out[f"force {k}"] = (q_force @ dy, f @ dr)
    for k, spring in enumerate(scene.forces[2:]):
        at_rest = spring.generalized_force(t, y, jnp.zeros_like(z), scene)
        out[f"spring {k}"] = (at_rest, -jax.grad(lambda yy: spring.potential_energy(t, yy, scene))(y))
        moving = spring.generalized_force(t, y, z, scene)
        rate = jax.jvp(lambda yy: spring.length(t, yy, scene), (y,), (z,))[1]
        out[f"damper {k}"] = ((moving - at_rest) @ z, -spring.damping * rate**2)
        out[f"rate {k}"] = (spring.length_rate(t, y, z, scene), rate)
    return out


@pytest.mark.slow  # one compile, ~3 s CPU: over the default suite's budget for a new test
def test_generalized_forces_are_the_virtual_work():
    rng = np.random.default_rng(3)
    law = fj.HarmonicLaw(1.5, 0.8, phase=0.2, offset=0.3)
    scene = fj.Scene(
        bodies=(fj.Body("rigid", _rigid_data(1)), fj.Body("flexible", _flexible_data(2))), constraints=(),
        forces=(fj.SpatialAppliedForce(0, 1, force=rng.normal(size=3), torque=rng.normal(size=3), magnitude=law),
                fj.SpatialAppliedForce(1, 0, force=rng.normal(size=3), torque=rng.normal(size=3), magnitude=law),
                fj.SpatialSpringDamper(0, 1, 1, 1, stiffness=30.0, damping=2.0, rest_length=0.4),
                fj.SpatialSpringDamper(1, 0, stiffness=20.0, damping=3.0, rest_length=0.5, point=(0.5, 1.0, -1.0))))
    p0 = 1.3 * fj.euler_parameters(rng.normal(size=3), 1.0)  # |p| = 1.3: the forces hold off the unit sphere
    p1 = fj.euler_parameters(rng.normal(size=3), 2.0)
    # The flexible body at q = 0, where its marker frame is a rotation and dphi is exact (to first order in q the
    # package's torque acts on A (dpi' + Psi dq), as its joints do).
    y = jnp.asarray(np.concatenate([rng.normal(size=3), p0, rng.normal(size=3), p1, np.zeros(N_Q)]))
    dy, z = jnp.asarray(rng.normal(size=16)), jnp.asarray(rng.normal(size=16))
    out = {k: (np.asarray(a), np.asarray(b)) for k, (a, b) in _virtual_work_check(scene, y, dy, z).items()}
    for name, (got, want) in out.items():
        assert np.max(np.abs(got - want)) <= ROUND_OFF * max(np.max(np.abs(want)), 1.0), f"{name}: {got} vs {want}"
    assert abs(out["damper 0"][1]) > 1e-2 and abs(out["damper 1"][1]) > 1e-2, "the dampers work at this state"
    # The flexible body deformed (q != 0; the same program): all but the torque on it (first order in q) hold.
    deformed = _virtual_work_check(scene, y.at[14:].set(jnp.asarray([0.2, -0.3])), dy, z)
    for name, (got, want) in deformed.items():
        if name != "load 1":
            got, want = np.asarray(got), np.asarray(want)
            assert np.max(np.abs(got - want)) <= ROUND_OFF * max(np.max(np.abs(want)), 1.0), f"{name} (q != 0)"


def test_bad_force_input_is_refused():
    with pytest.raises(ValueError, match="non-zero force or torque"):
        fj.SpatialAppliedForce(0, 0)
    with pytest.raises(ValueError, match=r"finite \(3,\) vector"):
        fj.SpatialAppliedForce(0, 0, force=(1.0, 0.0))
    with pytest.raises(ValueError, match="stiffness must be a number"):
        fj.SpatialSpringDamper(0, 0, stiffness="stiff")
    with pytest.raises(ValueError, match="ground point"):
        fj.SpatialSpringDamper(0, 0, stiffness=1.0, point=(0.0, 1.0))
    planar = fj.Body("planar", fj.rigid_body_data(1.0, [0.0, 0.0], 0.1, [[0.0, 0.0]]))
    for force in (fj.SpatialAppliedForce(0, 0, torque=(0.0, 0.0, 1.0)), fj.SpatialSpringDamper(0, 0, stiffness=1.0)):
        scene = fj.Scene(bodies=(planar,), constraints=(), forces=(force,))
        with pytest.raises(ValueError, match="is planar"):  # refused where the scene is traced, before any arithmetic
            force.generalized_force(0.0, jnp.zeros(3), jnp.zeros(3), scene)


# --- energy balances along a motion (slow) ------------------------------------------------------------------------
RTOL, ATOL = 1e-10, 1e-12
# Integrated at rtol 1e-10 / atol 1e-12 (Dopri8, a few hundred steps): the global error of the state is ~1e-8 of
# its size, and the energies (smooth in the state) carry that relative error. The dissipated energy is the
# objective, integrated with the motion to the same tolerance.
SOLVER_DRIFT = 1e-7
# The applied work is integrated here by Simpson's rule on 401 output times (h = 2.5 ms): error
# ~ h^4 T max|P''''| / 180 with the power P varying at <= ~20 rad/s: (0.0025 * 20)^4 / 180 ~ 4e-8 of max|P| T.
SIMPSON = 1e-6
G = np.array([0.0, 0.0, -9.81])
T1 = 1.0
LAW = fj.HarmonicLaw(2.0, 1.3, phase=0.3, offset=0.5)
FORCE, TORQUE = np.array([1.0, -0.5, 2.0]), np.array([0.3, 0.4, -0.2])


def _dissipation(t, y_r, z_r, scene):
    return sum(f.damping * f.length_rate(t, y_r, z_r, scene) ** 2 for f in scene.forces
               if isinstance(f, fj.SpatialSpringDamper))


def _energy_problem(damping):
    hanging = _rigid_data(11)
    flexible = _flexible_data(12)
    free = _rigid_data(13, n_markers=1)
    scene = fj.Scene(
        bodies=(fj.Body("hanging", hanging), fj.Body("flexible", flexible), fj.Body("free", free)), constraints=(),
        forces=(fj.Gravity(tuple(G)),
                fj.SpatialSpringDamper(0, 0, stiffness=60.0, damping=damping, rest_length=0.8, point=(0.0, 0.0, 1.0)),
                fj.SpatialSpringDamper(0, 1, 1, 0, stiffness=40.0, damping=damping, rest_length=0.5),
                fj.SpatialAppliedForce(2, 0, force=FORCE, torque=TORQUE, magnitude=LAW)))
    rng = np.random.default_rng(14)
    positions = np.concatenate([[0.2, -0.1, 0.0], fj.euler_parameters([1.0, 0.0, 0.3], 0.4),
                                [0.5, 0.3, -0.6], fj.euler_parameters([0.0, 1.0, 0.2], 0.7), [0.01, -0.02],
                                [2.0, 0.0, 0.0], fj.euler_parameters([0.3, 0.2, 1.0], 0.5)])
    spins = [rng.normal(size=3) for _ in range(3)]
    velocities = np.concatenate([rng.normal(size=3), fj.euler_parameter_rates(positions[3:7], spins[0]),
                                 rng.normal(size=3), fj.euler_parameter_rates(positions[10:14], spins[1]), [0.3, -0.2],
                                 rng.normal(size=3), fj.euler_parameter_rates(positions[19:23], spins[2])])
    return fj.Problem(scene, T1, positions=positions, velocities=velocities,
                      objective=fj.FunctionIntegrand(_dissipation))


@eqx.filter_jit
def _balances(scene, ts, positions, velocities):
    g = jnp.asarray(G)

    def one(t, y, z):
        y0, z0 = scene.body_coordinates(0, y), scene.body_coordinates(0, z)
        y1, z1 = scene.body_coordinates(1, y), scene.body_coordinates(1, z)
        y2, z2 = scene.body_coordinates(2, y), scene.body_coordinates(2, z)
        data = [b.data for b in scene.bodies]
        springs = scene.forces[1].potential_energy(t, y, scene) + scene.forces[2].potential_energy(t, y, scene)
        pair = (_rigid_body.kinetic_energy(data[0], y0, z0) + _flexible_body.kinetic_energy(data[1], y1, z1)
                + _rigid_body.gravity_potential(data[0], g, y0) + _flexible_body.gravity_potential(data[1], g, y1)
                + _flexible_body.strain_energy(data[1], y1) + springs)
        free = _rigid_body.kinetic_energy(data[2], y2, z2) + _rigid_body.gravity_potential(data[2], g, y2)
        f, tau = scene.forces[3].loads(t)
        v_p = jax.jvp(lambda yy: scene.marker_position(2, 0, yy), (y,), (z,))[1]
        omega = rotation_matrix(y2[3:7]) @ angular_velocity(y2[3:7], z2[3:7])
        lin, _ = _rigid_body.momenta(data[2], y2, z2)
        return pair, free, f @ v_p + tau @ omega, lin

    return jax.vmap(one)(ts, positions, velocities)


def _simpson(values, ts):
    h = ts[1] - ts[0]
    return h / 3 * (values[0] + values[-1] + 4 * values[1:-1:2].sum() + 2 * values[2:-1:2].sum())


@pytest.fixture(scope="module")
def balances():
    damped = _energy_problem(damping=1.5)
    undamped = damped.with_scene(eqx.tree_at(lambda s: (s.forces[1].damping, s.forces[2].damping), damped.scene,
                                             (jnp.asarray(0.0), jnp.asarray(0.0))))
    ts = jnp.linspace(0.0, T1, 401)
    out = {}
    for name, problem in (("damped", damped), ("undamped", undamped)):
        traj = fj.simulate(problem, ts=ts, rtol=RTOL, atol=ATOL)
        pair, free, power, lin = _balances(problem.scene, traj.ts, traj.positions, traj.velocities)
        out[name] = (float(traj.psi), np.asarray(pair), np.asarray(free), np.asarray(power), np.asarray(lin))
    return np.asarray(ts), out, float(damped.scene.bodies[2].data.mass)


@pytest.mark.slow
def test_spring_damper_energy_balance(balances):
    """Without damping `T + V` of the hanging pair is constant; with damping it falls by `int c l'^2 dt`."""
    _, out, _ = balances
    psi, pair = out["undamped"][:2]
    assert psi == 0.0
    assert np.ptp(pair) <= SOLVER_DRIFT * np.max(np.abs(pair)), f"undamped energy drifts by {np.ptp(pair)}"
    psi, pair = out["damped"][:2]
    assert psi > 1e-2 * np.max(np.abs(pair)), "the dampers dissipate a sizeable share of the energy"
    lost = pair[0] - pair[-1]
    assert abs(lost - psi) <= SOLVER_DRIFT * np.max(np.abs(pair)), f"lost {lost}, dissipated {psi}"


@pytest.mark.slow
def test_applied_force_and_torque_work(balances):
    """`int (F . rdot_P + tau . omega) dt = Delta (T + V_gravity)` of the driven body, and
    `L(t) - L(0) = F0 int phi dt + m g t` with `int phi = offset t - A (cos(w t + ph) - cos ph) / w`."""
    ts, out, mass = balances
    for name in ("damped", "undamped"):
        _, _, free, power, lin = out[name]
        work = _simpson(power, ts)
        assert abs(work) > 0.1 * np.max(np.abs(free)), "the loads do sizeable work"
        assert abs((free[-1] - free[0]) - work) <= SIMPSON * np.max(np.abs(power)) * T1 + SOLVER_DRIFT * np.max(
            np.abs(free)), f"{name}: work {work}, energy change {free[-1] - free[0]}"
        w = 2 * np.pi * 1.3
        impulse = 0.5 * ts - 2.0 * (np.cos(w * ts + 0.3) - np.cos(0.3)) / w
        want = lin[0] + impulse[:, None] * FORCE + mass * ts[:, None] * G
        assert np.max(np.abs(lin - want)) <= SOLVER_DRIFT * np.max(np.abs(lin)), f"{name}: momentum"
