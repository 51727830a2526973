"""Equations of motion against an independent mesh Lagrangian, energy balances, constraints, kinematics.

The reference model here is written from scratch: every node of the finite element mesh moves as
`r_n = R + A(theta) (c_n + Phi_n q)`, `T = 1/2 rdot_n^T M rdot_n`, `V = 1/2 u^T K u` (plus the
potentials of gravity and springs), and the rigid links are sets of point masses with the same
mass, first moment and inertia. Its mass matrix and forces come from automatic differentiation;
the constrained accelerations from the Lagrange-multiplier (index-1 DAE) system

`[[M, C^T], [C, 0]] [a; lambda] = [h; -gamma]`,

which the minimal-coordinate model (coordinate partitioning) must reproduce.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax
from ffr_jax._dynamics._model import MinimalModel
from helpers import assert_close_relative, rotation


# Tolerances, named for what they bound.
EOM_RTOL = 1e-10  # body-data equations of motion vs. automatic differentiation of the mesh Lagrangian
ENERGY_RTOL = 1e-8  # drift of T + V of the conservative pendulum over 2 s (rtol 1e-10 integration)
POWER_RTOL = 1e-8  # d(T + V)/dt vs. the driver's power, pointwise
CONSTRAINT_TOL = 1e-10  # position and velocity constraints along trajectories
KINEMATICS_TOL = 1e-12  # rigid slider-crank vs. its closed-form kinematics


# --- the independent mesh model ------------------------------------------------------------------
class MeshBody:
    """Nodes with a mass matrix (FE rod) or point masses (rigid link), for the reference Lagrangian."""

    def __init__(self, coords, mass, stiffness=None, modes=None):
        self.coords = jnp.asarray(coords)  # (n, 2) undeformed positions in the body frame
        self.mass = jnp.asarray(mass)  # (2n, 2n) consistent mass, or (n,) point masses
        self.stiffness = stiffness
        self.modes = modes  # (2n, n_q) or None

    @property
    def n_coordinates(self):
        return 3 + (0 if self.modes is None else self.modes.shape[1])

    def positions(self, y_b):
        u = self.coords
        if self.modes is not None:
            u = u + (self.modes @ y_b[3:]).reshape(-1, 2)
        return y_b[:2] + u @ rotation(y_b[2]).T

    def mass_product(self, a, b):
        """`a^T M b` for nodal vectors `(n, 2)`."""
        if self.mass.ndim == 1:
            return jnp.sum(self.mass[:, None] * a * b)
        return a.ravel() @ self.mass @ b.ravel()

    def kinetic_energy(self, y_b, z_b):
        rdot = jax.jvp(self.positions, (y_b,), (z_b,))[1]
        return 0.5 * self.mass_product(rdot, rdot)

    def potential_energy(self, y_b, g):
        r = self.positions(y_b)
        v = -self.mass_product(jnp.broadcast_to(g, r.shape), r)
        if self.modes is not None:
            u = self.modes @ y_b[3:]
            v = v + 0.5 * u @ self.stiffness @ u
        return v


def rod_mesh_body(case, x):
    k, m = case.fe_matrices(x)
    return MeshBody(case.mesh.nodes, m, k, case.modes(x).modes)


def bar_mesh_body(data):
    """A uniform bar from the origin to marker 1 as three Simpson point masses (same m, s0, J)."""
    length = float(data.marker_positions[1, 0])
    m = float(data.mass)
    body = MeshBody([[0.0, 0.0], [0.5 * length, 0.0], [length, 0.0]], jnp.array([m / 6, 2 * m / 3, m / 6]))
    np.testing.assert_allclose([m * length / 2, 0.0], data.first_moment, rtol=1e-14, err_msg="bar first moment")
    np.testing.assert_allclose(m * length**2 / 3, data.inertia, rtol=1e-14, err_msg="bar inertia")
    return body


def block_mesh_body(data):
    """A rigid body with its centre of mass at its frame origin as four point masses (same m, J)."""
    m, j = float(data.mass), float(data.inertia)
    a = np.sqrt(j / m)
    np.testing.assert_allclose(data.first_moment, 0.0, atol=1e-15, err_msg="block first moment")
    return MeshBody([[a, 0.0], [-a, 0.0], [0.0, a], [0.0, -a]], jnp.full(4, m / 4))


class MeshSystem:
    """The whole scene as mesh bodies, with gravity `g` and ground springs written out by hand."""

    def __init__(self, scene, bodies, g=(0.0, 0.0), springs=()):
        self.scene, self.bodies, self.g, self.springs = scene, bodies, jnp.asarray(g), springs

    def split(self, v_r):
        out, o = [], 0
        for b in self.bodies:
            out.append(v_r[o : o + b.n_coordinates])
            o += b.n_coordinates
        return out

    def kinetic_energy(self, y_r, z_r):
        return sum(b.kinetic_energy(y, z) for b, y, z in zip(self.bodies, self.split(y_r), self.split(z_r)))

    def potential_energy(self, y_r):
        v = sum(b.potential_energy(y, self.g) for b, y in zip(self.bodies, self.split(y_r)))
        for body, point, anchor, k, rest in self.springs:
            y_b = self.split(y_r)[body]
            r = y_b[:2] + rotation(y_b[2]) @ point
            v = v + 0.5 * k * (jnp.linalg.norm(r - anchor) - rest) ** 2
        return v

    def mass_matrix(self, y_r, z_r):
        return jax.hessian(self.kinetic_energy, argnums=1)(y_r, z_r)

    def lagrange_forces(self, y_r, z_r):
        """`d/dt dT/dz - dT/dy + dV/dy` at zero acceleration (the negative of `h_a`)."""
        dt_dz = jax.grad(self.kinetic_energy, argnums=1)
        return (jax.jacfwd(dt_dz, argnums=0)(y_r, z_r) @ z_r - jax.grad(self.kinetic_energy, argnums=0)(y_r, z_r)
                + jax.grad(self.potential_energy)(y_r))

    def dae_accelerations(self, t, y_r, z_r):
        """`(a, lambda)` of `[[M, C^T], [C, 0]] [a; lambda] = [h; -gamma]` with `gamma = w^T c'' w`, `w = (1, z)`."""
        m = self.mass_matrix(y_r, z_r)
        h = -self.lagrange_forces(y_r, z_r)

        def c(ty):
            return self.scene.constraint_residual(ty[0], ty[1:])

        ty = jnp.concatenate([jnp.asarray(t)[None], y_r])
        w = jnp.concatenate([jnp.ones(1), z_r])
        cmat = jax.jacfwd(c)(ty)[:, 1:]
        gamma = jnp.einsum("i,kij,j->k", w, jax.hessian(c)(ty), w)
        n, n_c = y_r.size, cmat.shape[0]
        kkt = jnp.block([[m, cmat.T], [cmat, jnp.zeros((n_c, n_c))]])
        sol = jnp.linalg.solve(kkt, jnp.concatenate([h, -gamma]))
        return sol[:n], sol[n:]


# --- the cases compared --------------------------------------------------------------------------
X_VALUE = 0.5


def _scene(case, x):
    """`case.scene(x)` as one compiled program (eagerly, the FE and modal pipeline compiles op by op)."""
    return eqx.filter_jit(case.scene)(x)


@functools.cache
def pendulum():
    case = ffr_jax.cases.flexible_pendulum(10, 2, 3, t1=2.0)
    x = case.initial_design(X_VALUE)
    scene = _scene(case, x)
    return case, scene, MeshSystem(scene, [rod_mesh_body(case, x)], g=(0.0, -9.81))


@functools.cache
def slider_crank():
    case = ffr_jax.cases.slider_crank(10, 2, 3, t1=0.4, t_ramp=0.4, speed=8 * np.pi)
    x = case.initial_design(X_VALUE)
    scene = _scene(case, x)
    return case, scene, MeshSystem(scene, [rod_mesh_body(case, x)])


@functools.cache
def four_bar():
    case = ffr_jax.cases.four_bar(10, 2, 3, t1=0.5, t_ramp=0.25, speed=8 * np.pi)
    x = case.initial_design(X_VALUE)
    scene = _scene(case, x)
    crank, _, rocker = (b.data for b in scene.bodies)
    return case, scene, MeshSystem(scene, [bar_mesh_body(crank), rod_mesh_body(case, x), bar_mesh_body(rocker)])


@functools.cache
def rigid_slider_crank():
    case = ffr_jax.cases.rigid_slider_crank(driven=False)
    scene = case.scene
    crank, rod, slider = (b.data for b in scene.bodies)
    spring = scene.forces[0]
    springs = [(2, slider.marker_positions[0], spring.ground_point, float(spring.stiffness), float(spring.rest_length))]
    bodies = [bar_mesh_body(crank), bar_mesh_body(rod), block_mesh_body(slider)]
    return case, scene, MeshSystem(scene, bodies, springs=springs)


SYSTEMS = {"pendulum": pendulum, "slider_crank": slider_crank, "four_bar": four_bar,
           "rigid_slider_crank": rigid_slider_crank}


def random_state(case, scene, seed):
    """A consistent redundant state at a random time: random independent `(y, z)`, the rest by the model."""
    rng = np.random.default_rng(seed)
    model = case.model
    f = model.partition.n_independent
    t = jnp.asarray(rng.uniform(0.0, case.t1))
    y_ref = model.split(case.y_r0)[0]
    y = y_ref + jnp.asarray(rng.normal(scale=0.3, size=f))
    z = jnp.asarray(rng.normal(scale=3.0, size=f))
    y_r, z_r = jax.jit(lambda t, y, z: model.state(t, y, z, scene))(t, y, z)
    return t, y, z, y_r, z_r


# --- body data vs. the mesh Lagrangian -----------------------------------------------------------
@pytest.mark.parametrize("system", ["pendulum", "four_bar", "rigid_slider_crank"])
@pytest.mark.parametrize("seed", [0, 1])
def test_mass_matrix_and_forces_equal_mesh_lagrangian(system, seed):
    """`M(y_r)` is the Hessian of `T` in the velocities and `-h_a` is `d/dt dT/dz - dT/dy + dV/dy`.

    At random, unconstrained states (every coordinate random, elastic ones included).
    """
    case, scene, mesh = SYSTEMS[system]()
    rng = np.random.default_rng(seed)
    n = scene.n_coordinates
    y_r = jnp.asarray(rng.normal(scale=0.5, size=n))
    z_r = jnp.asarray(rng.normal(scale=3.0, size=n))
    t = jnp.asarray(0.1)
    # One compiled program per system (op-by-op evaluation of these derivatives is slow).
    terms = jax.jit(lambda t, y_r, z_r: (scene.mass_matrix(y_r), mesh.mass_matrix(y_r, z_r),
                                         -scene.applied_forces(t, y_r, z_r), mesh.lagrange_forces(y_r, z_r)))
    m_model, m_mesh, f_model, f_mesh = terms(t, y_r, z_r)
    assert_close_relative(m_model, m_mesh, EOM_RTOL, f"{system}: mass matrix")
    assert_close_relative(f_model, f_mesh, EOM_RTOL, f"{system}: quadratic-velocity, elastic and applied forces")


@pytest.mark.parametrize("system", ["pendulum", "slider_crank", "four_bar", "rigid_slider_crank"])
def test_minimal_accelerations_equal_lagrange_multiplier_dae(system):
    """Coordinate partitioning gives the accelerations of the Lagrange-multiplier system of the mesh model."""
    case, scene, mesh = SYSTEMS[system]()
    model = case.model

    @jax.jit
    def accelerations(t, y, z, y_r, z_r):
        a_dae, _ = mesh.dae_accelerations(t, y_r, z_r)
        zdot = model.accelerations(t, y_r, z_r, scene)
        # The redundant accelerations follow by differentiating the model's velocity map along the motion.
        zdot_r = jax.jvp(lambda tt, yy, zz: model.state(tt, yy, zz, scene)[1], (t, y, z), (jnp.ones_like(t), z, zdot))[1]
        return a_dae, zdot, zdot_r

    for seed in (0, 1):
        t, y, z, y_r, z_r = random_state(case, scene, seed)
        a_dae, zdot, zdot_r = accelerations(t, y, z, y_r, z_r)
        assert_close_relative(zdot, model.split(a_dae)[0], EOM_RTOL, f"{system}: independent accelerations")
        assert_close_relative(zdot_r, a_dae, EOM_RTOL, f"{system}: redundant accelerations")


# --- trajectories ---------------------------------------------------------------------------------
def _energy(scene, t, y_r, z_r):
    return scene.kinetic_energy(y_r, z_r) + scene.potential_energy(t, y_r)


@functools.cache
def trajectory(system, rtol, atol, n_save):
    case, scene, _ = SYSTEMS[system]()
    ts = jnp.linspace(case.t0, case.t1, n_save)
    run = jax.jit(lambda s: ffr_jax.simulate(case.model, s, case.t0, case.t1, case.y_r0, case.z_r0, rtol=rtol,
                                             atol=atol, ts=ts, jump_ts=case.jump_ts))
    traj = run(scene)
    states = jax.jit(jax.vmap(lambda t, y, z: case.model.state(t, y, z, scene)))(traj.ts, traj.ys, traj.zs)
    return traj, states


def test_pendulum_conserves_energy():
    """Undamped, undriven flexible pendulum under gravity: `T + V` constant over 2 s."""
    case, scene, _ = pendulum()
    traj, (y_r, z_r) = trajectory("pendulum", 1e-10, 1e-12, 21)
    energy = jax.jit(jax.vmap(lambda t, y, z: _energy(scene, t, y, z)))(traj.ts, y_r, z_r)
    mass = float(scene.bodies[0].data.mass)
    scale = mass * 9.81 * case.mesh.length  # the energy exchanged in the swing is of this order
    # Released from rest at -45 deg, the centre of mass (at L/2) drops by (1 - sin 45 deg) L/2 when
    # the rod passes the vertical: a rigid rod's kinetic energy there. The saved states sample it.
    swing = scale * 0.5 * (1.0 - np.sin(np.pi / 4))
    kinetic = jax.jit(jax.vmap(scene.kinetic_energy))(y_r, z_r)
    assert 0.8 * swing < float(jnp.max(kinetic)) < 1.01 * swing, "the pendulum should swing through the vertical"
    drift = float(jnp.max(jnp.abs(energy - energy[0])))
    assert drift <= ENERGY_RTOL * scale, f"T + V drifted by {drift:.3e} (scale {scale:.3e})"


def test_driver_power_equals_energy_rate():
    """Slider–crank during run-up: `d(T + V)/dt` equals the power of the constraint forces, `lambda^T c_t`.

    With `M a + C^T lambda = h`, the constraint forces are `-C^T lambda` and their power is
    `-z_r^T C^T lambda = lambda^T c_t` (from `C z_r + c_t = 0`); only the rheonomic crank pin
    works. `d(T + V)/dt` is the derivative of the model's energy along its own vector field.
    """
    case, scene, mesh = slider_crank()
    model = case.model
    traj, (y_r, z_r) = trajectory("slider_crank", 1e-8, 1e-10, 21)

    def rates(t, y, z, y_r, z_r):
        zdot = model.accelerations(t, y_r, z_r, scene)
        de_dt = jax.jvp(lambda tt, yy, zz: _energy(scene, tt, *model.state(tt, yy, zz, scene)),
                        (t, y, z), (jnp.ones_like(t), z, zdot))[1]
        _, lam = mesh.dae_accelerations(t, y_r, z_r)
        c_t = jax.jacfwd(scene.constraint_residual, argnums=0)(t, y_r)
        return de_dt, lam @ c_t

    de_dt, power = jax.jit(jax.vmap(rates))(traj.ts, traj.ys, traj.zs, y_r, z_r)
    assert float(jnp.max(jnp.abs(power))) > 1.0, "the driver should do work during the run-up"
    assert_close_relative(de_dt, power, POWER_RTOL, "d(T + V)/dt vs. driver power")


@pytest.mark.parametrize("system,rtol,atol,n_save", [("pendulum", 1e-10, 1e-12, 21),
                                                    ("slider_crank", 1e-8, 1e-10, 21),
                                                    ("four_bar", 1e-6, 1e-8, 41)])
def test_constraints_hold_along_trajectories(system, rtol, atol, n_save):
    """Position and velocity constraints hold at every saved state of a simulation."""
    case, scene, _ = SYSTEMS[system]()
    traj, (y_r, z_r) = trajectory(system, rtol, atol, n_save)
    pos = jax.jit(jax.vmap(scene.constraint_residual))(traj.ts, y_r)
    vel = jax.jit(jax.vmap(lambda t, y, z: case.model.velocity_constraint(t, y, z, scene)))(traj.ts, y_r, z_r)
    assert float(jnp.max(jnp.abs(pos))) <= CONSTRAINT_TOL, f"{system}: position constraints {jnp.max(jnp.abs(pos))}"
    assert float(jnp.max(jnp.abs(vel))) <= CONSTRAINT_TOL, f"{system}: velocity constraints {jnp.max(jnp.abs(vel))}"


def rigid_rocker_angle(phi, crank, coupler, rocker, pivot):
    """Rocker angle of the rigid four-bar, rocker tip to the left of the line from crank pin to pivot."""
    pin = crank * np.array([np.cos(phi), np.sin(phi)])
    d = np.linalg.norm(pivot - pin)
    e = (pivot - pin) / d
    along = (coupler**2 - rocker**2 + d**2) / (2 * d)
    tip = pin + along * e + np.sqrt(coupler**2 - along**2) * np.array([-e[1], e[0]])
    return np.arctan2(tip[1] - pivot[1], tip[0] - pivot[0])


def test_four_bar_turns_full_circles_on_its_branch():
    """The crank makes more than a full turn; the rocker stays on the branch the linkage was assembled on."""
    case, scene, _ = four_bar()
    traj, (y_r, _) = trajectory("four_bar", 1e-6, 1e-8, 41)
    crank, rocker = y_r[:, 2], y_r[:, -1]
    assert float(crank[-1] - crank[0]) > 2 * np.pi, "the crank should turn at least once"
    pivot = np.asarray(scene.constraints[4].point)
    a, b = (float(scene.bodies[i].data.marker_positions[1, 0]) for i in (0, 2))
    rigid_rocker = np.array([rigid_rocker_angle(p, a, case.mesh.length, b, pivot) for p in np.asarray(crank)])
    # Elastic chord changes are ~1e-4 m here, so the flexible rocker angle stays within 1e-2 rad of the
    # rigid one on the same branch; the other branch is ~1 rad away.
    assert float(jnp.max(jnp.abs(rocker - rigid_rocker))) < 1e-2


def test_rigid_slider_crank_matches_closed_form_kinematics():
    """Driven rigid slider–crank (no degree of freedom): `x_B = eps cos phi + sqrt(l^2 - eps^2 sin^2 phi)`.

    The positions are found by Newton continuation from the assembled initial state (the case's
    closed-form guess is not used), so they come from the constraints alone.
    """
    case = ffr_jax.cases.rigid_slider_crank(t1=1.0, driven=True)
    scene, model = case.scene, case.model
    assert model.partition.n_independent == 0
    eps = float(scene.bodies[0].data.marker_positions[1, 0])
    length = float(scene.bodies[1].data.marker_positions[1, 0])
    plain = MinimalModel(partition=model.partition, reference_dependent=model.reference_dependent)

    @jax.jit
    def step(y_d, t):
        y_r = MinimalModel(partition=plain.partition, reference_dependent=y_d).positions(t, jnp.zeros(0), scene)
        return y_r, y_r

    ts = jnp.linspace(0.0, case.t1, 201)
    _, y_r = jax.lax.scan(step, model.reference_dependent, ts)
    phi = y_r[:, 2]
    assert float(phi[-1]) > 2 * np.pi, "the crank should turn at least once"
    expected = eps * jnp.cos(phi) + jnp.sqrt(length**2 - (eps * jnp.sin(phi)) ** 2)
    assert float(jnp.max(jnp.abs(y_r[:, 6] - expected))) <= KINEMATICS_TOL
    assert float(jnp.max(jnp.abs(y_r[:, 7]))) <= KINEMATICS_TOL, "the slider leaves the x-axis"
    # The same case simulates (its minimal state is empty) and reproduces the motion.
    traj = eqx.filter_jit(ffr_jax.simulate)(model, scene, case.t0, case.t1, case.y_r0, case.z_r0, ts=ts[::50],
                                            jump_ts=case.jump_ts)
    y_sim = jax.jit(jax.vmap(lambda t, y: model.positions(t, y, scene)))(traj.ts, traj.ys)
    np.testing.assert_allclose(y_sim, y_r[::50], atol=KINEMATICS_TOL)


def test_free_rigid_slider_crank_follows_closed_form_kinematics():
    """Free rigid slider–crank on its spring: along the simulated crank angle the slider obeys the closed form."""
    case, scene, _ = rigid_slider_crank()
    traj, (y_r, z_r) = trajectory("rigid_slider_crank", 1e-10, 1e-12, 21)
    eps = float(scene.bodies[0].data.marker_positions[1, 0])
    length = float(scene.bodies[1].data.marker_positions[1, 0])
    phi = y_r[:, 2]
    expected = eps * jnp.cos(phi) + jnp.sqrt(length**2 - (eps * jnp.sin(phi)) ** 2)
    assert float(jnp.max(jnp.abs(y_r[:, 6] - expected))) <= KINEMATICS_TOL
    energy = jax.jit(jax.vmap(lambda t, y, z: _energy(scene, t, y, z)))(traj.ts, y_r, z_r)
    assert float(jnp.max(jnp.abs(energy - energy[0]))) <= ENERGY_RTOL * float(energy[0]), "spring system energy"
