"""Joint forces and driver torques recovered from the minimal-coordinate solution (issue 31):
against an independent index-1 DAE transcription solved with SciPy, against the Newton–Euler
balance of every body (rigid and flexible), and the gradients of a joint-load objective."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate

import ffr_jax as fj
from ffr_jax._dynamics import _body_dynamics

# --- an independent transcription of the free rigid slider-crank -----------------------------------
# Centre-of-mass coordinates q = (x1, y1, th1 | x2, y2, th2 | x3, y3, th3) (ffr_jax uses frames at the
# crank pivot, the crank pin and the slider), diagonal mass matrix, constraints, Jacobian and
# gamma = (C qdot)_q qdot written by hand in the order and form of the scene's constraints
# (GroundRevolute, Revolute, Revolute, PointOnLine, AngleDriver). The multipliers of one constraint
# function are independent of the coordinates that describe the bodies, so they must agree.
EPS, L, M1, M2, M3, K, L0, W0, T1 = 0.1, 0.4, 0.5, 1.0, 2.0, 2.0e3, 0.4, 10.0, 0.5
MASS = np.diag([M1, M1, M1 * EPS**2 / 12, M2, M2, M2 * L**2 / 12, M3, M3, M3 * 1e-3])
NAMES = ("GroundRevolute(crank)", "Revolute(crank,rod)", "Revolute(rod,slider)", "PointOnLine(slider)",
         "AngleDriver(slider)")
# Both integrations carry a global error of about 10 x their rtol (measured 1e-9 on the crank angle for
# ffr_jax at its default rtol 1e-10; SciPy runs at 1e-12). The multipliers m omega^2 r + k x are smooth
# in the state with a relative sensitivity of order one per unit of state (omega ~ 10 rad/s, |y| < 1),
# so they differ by ~1e-9 relative; 1e-7 leaves a factor 100 for error growth. Measured 1.8e-9.
ALONG_MOTION = 1e-7
# At the same state both are solutions of linear systems (the augmented DAE system, cond ~1e5 with the
# slider's tiny inertia 2e-3; ffr_jax's minimal solve and C_d^-T): round-off n eps cond ~ 2e-10.
SAME_STATE = 1e-9


def _e(th):
    return np.array([np.cos(th), np.sin(th)])


def _ep(th):
    return np.array([-np.sin(th), np.cos(th)])


def _dae_accelerations_and_multipliers(q, v):
    th1, th2, w1, w2 = q[2], q[5], v[2], v[5]
    c, g = np.zeros((8, 9)), np.zeros(8)
    c[0:2, 0:2], c[0:2, 2], g[0:2] = np.eye(2), -EPS / 2 * _ep(th1), EPS / 2 * w1**2 * _e(th1)
    c[2:4, 0:2], c[2:4, 2], c[2:4, 3:5], c[2:4, 5] = np.eye(2), EPS / 2 * _ep(th1), -np.eye(2), L / 2 * _ep(th2)
    g[2:4] = -EPS / 2 * w1**2 * _e(th1) - L / 2 * w2**2 * _e(th2)
    c[4:6, 3:5], c[4:6, 5], c[4:6, 6:8], g[4:6] = np.eye(2), L / 2 * _ep(th2), -np.eye(2), -L / 2 * w2**2 * _e(th2)
    c[6, 7] = c[7, 8] = 1.0
    d = q[6:8]
    f = np.zeros(9)
    f[6:8] = -K * (np.linalg.norm(d) - L0) * d / np.linalg.norm(d)
    sol = np.linalg.solve(np.block([[MASS, c.T], [c, np.zeros((8, 8))]]), np.concatenate([f, -g]))
    return sol[:9], sol[9:]


def _frame_state(q, v):
    """ffr_jax's redundant state from the centre-of-mass one (frames at pivot, pin and slider)."""
    y_r, z_r = q.copy(), v.copy()
    for b, half in ((0, EPS / 2), (1, L / 2)):
        th, w = q[3 * b + 2], v[3 * b + 2]
        y_r[3 * b : 3 * b + 2] -= half * _e(th)
        z_r[3 * b : 3 * b + 2] -= half * w * _ep(th)
    return y_r, z_r


@pytest.fixture(scope="module")
def reference():
    q0 = np.array([EPS / 2, 0, 0, EPS + L / 2, 0, 0, EPS + L, 0, 0])
    v0 = np.array([0, W0 * EPS / 2, W0, 0, W0 * EPS / 2, -W0 * EPS / L, 0, 0, 0])
    ts = np.linspace(0.0, T1, 6)
    res = scipy.integrate.solve_ivp(
        lambda t, s: np.concatenate([s[9:], _dae_accelerations_and_multipliers(s[:9], s[9:])[0]]),
        (0.0, T1), np.concatenate([q0, v0]), method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-12)
    assert res.success
    return ts, res.y.T


@pytest.fixture(scope="module")
def rigid():
    problem = fj.cases.rigid_slider_crank(T1, driven=False)
    assert problem.scene.forces[0].stiffness == K and float(problem.scene.bodies[2].data.mass) == M3
    traj = fj.simulate(problem, ts=jnp.linspace(0.0, T1, 6))
    return problem, traj, fj.joint_forces(problem, traj), fj.accelerations(problem, traj)


def _stack(forces):
    return np.concatenate([np.asarray(forces[n].multipliers) for n in NAMES], axis=-1)


def test_multipliers_equal_an_independent_dae_along_the_motion(reference, rigid):
    _, states = reference
    _, _, forces, _ = rigid
    lam_ref = np.array([_dae_accelerations_and_multipliers(s[:9], s[9:])[1] for s in states])
    err = np.max(np.abs(_stack(forces) - lam_ref))
    assert err <= ALONG_MOTION * np.max(np.abs(lam_ref)), f"multipliers along the motion differ by {err:.3e}"


def test_multipliers_and_accelerations_equal_the_dae_at_the_same_states(reference):
    ts, states = reference
    problem = fj.cases.rigid_slider_crank(T1, driven=False)
    frames = [_frame_state(s[:9], s[9:]) for s in states]
    y_r, z_r = jnp.asarray([f[0] for f in frames]), jnp.asarray([f[1] for f in frames])
    at = eqx.filter_jit(jax.vmap(lambda t, y, z: fj.constraint_multipliers(problem.model, t, y, z, problem.scene)))
    zdot_r, lam = at(jnp.asarray(ts), y_r, z_r)
    ref = [_dae_accelerations_and_multipliers(s[:9], s[9:]) for s in states]
    lam_ref = np.array([r[1] for r in ref])
    assert np.max(np.abs(np.asarray(lam) - lam_ref)) <= SAME_STATE * np.max(np.abs(lam_ref)), "multipliers"
    # Angular accelerations are the same coordinates in both descriptions.
    acc_ref = np.array([r[0] for r in ref])[:, 2::3]
    assert np.max(np.abs(np.asarray(zdot_r)[:, 2::3] - acc_ref)) <= SAME_STATE * np.max(np.abs(acc_ref)), \
        "angular accelerations"


# --- Newton–Euler balance of each body ----------------------------------------------------------------
# The balance is an identity of exact arithmetic; both sides are sums of forces of size F formed from
# solutions of systems with condition <= 1e5 (C_d, Mbar): round-off n eps cond F ~ 1e-10 F. 1e-9 F.
BALANCE = 1e-9


def _loads_on_bodies(scene, y_r, forces):
    """`[(body, point, force)]` and `[(body, torque)]` of every joint, from its reported JointForce."""
    points, torques = [], []
    for c, name in zip(scene.constraints, fj.joint_names(scene)):
        jf = forces[name]
        if isinstance(c, fj.Revolute):
            points += [(c.body_i, c.marker_i, jf.force), (c.body_j, c.marker_j, -jf.force)]
        elif isinstance(c, (fj.GroundRevolute, fj.CrankPin, fj.PointOnLine)):
            points.append((c.body, c.marker, jf.force))
        elif isinstance(c, fj.AngleDriver):
            torques.append((c.body, jf.torque))
        else:
            raise AssertionError(f"no oracle for {type(c).__name__}")
    return points, torques


def _newton_euler_residuals(scene, t, y_r, z_r, a_r, forces):
    """Per body: `m a_c - sum F` (centre of mass from the body data's first moments, differentiated twice
    along the motion) and the body's generalized balance `M_b a_b - h_b - sum_P (dr_P/dy_b)^T F_P - tau e_theta`
    (every row, modal ones included). Returns the residuals and the size of the largest term."""
    points, torques = _loads_on_bodies(scene, y_r, forces)
    applied = sum((f.generalized_force(t, y_r, z_r, scene) for f in scene.forces), jnp.zeros_like(y_r))
    h = scene.applied_forces(t, y_r, z_r)
    out = []
    for b, body in enumerate(scene.bodies):
        d = body.data
        y_b, z_b, a_b = (scene.body_coordinates(b, v) for v in (y_r, z_r, a_r))

        def first_moment(y):
            return d.mass * y[:2] + _body_dynamics.rotate(y[2], d.first_moment + d.modal_moment @ y[3:])

        velocity = lambda y: jax.jvp(first_moment, (y,), (z_b,))[1]  # noqa: E731
        momentum_rate = jax.jvp(velocity, (y_b,), (z_b,))[1] + jax.jacfwd(first_moment)(y_b) @ a_b
        joint_force = sum((f for (bb, _, f) in points if bb == b), jnp.zeros(2))
        force_residual = momentum_rate - joint_force - scene.body_coordinates(b, applied)[:2]
        generalized = _body_dynamics.body_mass_matrix(d, y_b) @ a_b - scene.body_coordinates(b, h)
        for bb, marker, f in points:
            if bb == b:
                generalized -= jax.jacfwd(lambda y: _body_dynamics.marker_position(d, marker, y))(y_b).T @ f
        for bb, tau in torques:
            if bb == b:
                generalized = generalized.at[2].add(-tau)
        scale = max(float(jnp.max(jnp.abs(momentum_rate))), float(jnp.max(jnp.abs(joint_force))),
                    float(jnp.max(jnp.abs(scene.body_coordinates(b, h)))))
        out.append((body.name, float(jnp.max(jnp.abs(force_residual))), float(jnp.max(jnp.abs(generalized))), scale))
    return out


def _check_balance(problem, traj, forces, accelerations):
    for k in range(1, len(traj.ts)):
        at = jax.tree_util.tree_map(lambda v: v[k], forces)
        for name, force_res, gen_res, scale in _newton_euler_residuals(
                problem.scene, traj.ts[k], traj.positions[k], traj.velocities[k], accelerations[k], at):
            assert force_res <= BALANCE * scale, f"{name}: m a_c - sum F = {force_res:.3e} (scale {scale:.3e})"
            assert gen_res <= BALANCE * scale, f"{name}: generalized balance {gen_res:.3e} (scale {scale:.3e})"


def test_newton_euler_balance_rigid(rigid):
    problem, traj, forces, acc = rigid
    _check_balance(problem, traj, forces, acc)


@pytest.fixture(scope="module")
def flexible():
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    x = case.initial_design(0.5)
    traj = fj.simulate(case, x, ts=jnp.linspace(0.0, 0.1, 5))
    return case, x, traj, fj.joint_forces(case, traj, x), fj.accelerations(case, traj, x)


def test_newton_euler_balance_flexible(flexible):
    case, x, traj, forces, acc = flexible
    _check_balance(case.problem_for(x), traj, forces, acc)


def test_driver_power_is_the_rate_of_energy(flexible):
    """Without damping, the crank-pin torque times the crank speed is `d(T + V)/dt` (the point-on-line
    joint does no work on a frictionless line)."""
    case, x, traj, forces, acc = flexible
    problem = case.problem_for(x)
    scene = problem.scene
    assert not scene.forces, "the family rod has no force elements (else their power enters)"
    crank = scene.constraints[0]
    speed = jax.vmap(jax.grad(crank.angle))(traj.ts)
    power = np.asarray(forces["CrankPin(rod)"].torque * speed)

    def energy(t, y, z):
        return scene.kinetic_energy(y, z) + scene.potential_energy(t, y)

    rate = np.asarray(jax.vmap(lambda t, y, z, a: jax.jvp(lambda yy, zz: energy(t, yy, zz), (y, z), (z, a))[1])(
        traj.ts, traj.positions, traj.velocities, acc))
    # The energy rate is a difference of terms of size m v a; round-off of the multiplier solve (above).
    scale = np.max(np.abs(rate)) + np.max(np.abs(power))
    assert np.max(np.abs(power - rate)) <= BALANCE * scale, f"driver power vs dE/dt: {np.abs(power - rate).max():.3e}"


# --- the derivative of the multipliers ----------------------------------------------------------------------
# `constraint_multipliers` is differentiated as the solution of the augmented system (a custom JVP), not through
# its formula. Against central differences of the multipliers and accelerations themselves, at a state of the
# flexible family rod, along one direction in (t, y_r, z_r) and in every float parameter of the scene, each entry
# moved by its own size times a pattern in [-0.5, 1] (relative step h = 1e-4): truncation h^2 |f'''| ~ 1e-8 |f|
# (derivatives of relative order one per unit of relative change), plus the round-off of two solves, 2 x 1e-10
# |f| (SAME_STATE's argument), over 2 h: 1e-6 |f|. 1e-5 of the largest entry. Reverse mode is the transpose of
# the forward rule: <w, J v> = <J^T w, v> up to the round-off of the sums (1e-12 relative).
JVP_VS_CENTRAL_DIFFERENCES = 1e-5
TRANSPOSE = 1e-12


def test_multiplier_derivatives_equal_central_differences_and_transpose(flexible):
    case, x, traj, _, _ = flexible
    problem = case.problem_for(x)
    dyn, static = eqx.partition(problem.scene, eqx.is_inexact_array)

    @jax.jit
    def outputs(s):
        t, y_r, z_r, d = s
        return fj.constraint_multipliers(problem.model, t, y_r, z_r, eqx.combine(d, static))

    primal = (traj.ts[2], traj.positions[2], traj.velocities[2], dyn)
    leaves, treedef = jax.tree_util.tree_flatten(primal)
    direction = treedef.unflatten([jnp.linspace(1.0, -0.5, a.size).reshape(a.shape) * jnp.abs(a) for a in leaves])
    values, tangents = jax.jit(lambda s, v: jax.jvp(outputs, (s,), (v,)))(primal, direction)
    h = 1e-4
    shifted = [outputs(jax.tree_util.tree_map(lambda a, v: a + sign * h * v, primal, direction)) for sign in (1, -1)]
    for name, k in (("accelerations", 0), ("multipliers", 1)):
        fd = (shifted[0][k] - shifted[1][k]) / (2 * h)
        err = float(jnp.max(jnp.abs(tangents[k] - fd)))
        assert err <= JVP_VS_CENTRAL_DIFFERENCES * float(jnp.max(jnp.abs(values[k]))), f"JVP of the {name}: {err:.3e}"
    weights = tuple(jnp.linspace(-1.0, 2.0, v.size) for v in values)
    (pulled,) = jax.jit(lambda s, w: jax.vjp(outputs, s)[1](w))(primal, weights)
    left = sum(float(jnp.vdot(w, t)) for w, t in zip(weights, tangents))
    right = sum(float(jnp.vdot(p, v)) for p, v in zip(jax.tree_util.tree_leaves(pulled), jax.tree_util.tree_leaves(direction)))
    scale = max(sum(float(jnp.vdot(jnp.abs(w), jnp.abs(t))) for w, t in zip(weights, tangents)),
                sum(float(jnp.vdot(jnp.abs(p), jnp.abs(v))) for p, v in
                    zip(jax.tree_util.tree_leaves(pulled), jax.tree_util.tree_leaves(direction))))
    assert abs(left - right) <= TRANSPOSE * scale, f"<w, J v> = {left:.15e}, <J^T w, v> = {right:.15e}"


# --- bad input ------------------------------------------------------------------------------------------
def test_unknown_joint_and_quantity_are_refused(rigid):
    problem = rigid[0]
    with pytest.raises(ValueError, match="No joint 'Crank'.*GroundRevolute"):
        fj.JointLoad(problem, "Crank")
    with pytest.raises(ValueError, match="has no torque"):
        fj.JointLoad(problem, "Revolute(crank,rod)", "torque")
    with pytest.raises(ValueError, match="power must be"):
        fj.JointLoad(problem, "Revolute(crank,rod)", "force", power=0.5)
    with pytest.raises(ValueError, match="needs the design x"):
        fj.joint_forces(fj.cases.slider_crank(4, 2, 2, 0.1), rigid[1])


# --- gradients of a joint-load objective ----------------------------------------------------------------
# adjoint vs autodiff: autodiff is the exact derivative of the discrete forward solution (rtol 1e-10), the
# adjoint the continuous one from a backward solve (here at rtol 1e-10 too); both approximate the exact
# gradient to the solves' global errors times the sensitivity of the entry. The slider-mass entry
# differed by 4.8e-8 at the adjoint's default 1e-8 and by 9.7e-9 at 1e-10 (so the floor is the forward
# discretisation's, ~100 forward rtol); the stiffness entry by 8.5e-9. 1e-7 is test_sensitivity's bound
# (backward rtol 1e-8 x growth <= 10), 10x above the measured floor. Central differences with a relative
# step 1e-4: truncation ~ (1e-4)^2 |psi'''/psi'| (order one in the stiffness' relative units) plus the
# forward solves' noise 10 rtol / 1e-4 = 1e-5 at most; 1e-5 as test_sensitivity (measured 1.8e-9).
ADJOINT_VS_AUTODIFF = 1e-7
FINITE_DIFFERENCES = 1e-5
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-12)


def _forward_mode(psi_of, p):
    """`d psi / d p` by forward-mode differentiation through the solver (`jax.jacfwd`; `psi_of` solves with diffrax's
    `ForwardMode`): the exact derivative of the discrete forward solution, the same derivative `jax.grad` through the
    solver (`method="autodiff"`) gives, by tangents along the few parameters checked instead of a reverse pass over all
    of them. It compiles in a fraction of the reverse-mode program's time (one core, quiet: the rigid joint load's
    autodiff program 70 s, the crank-pin torque's 31 s)."""
    def both(p):
        value = psi_of(p)
        return value, value

    return np.asarray(jax.jit(jax.jacfwd(both, has_aux=True))(jnp.asarray(p))[0])


@pytest.mark.slow
def test_joint_load_gradient_adjoint_autodiff_fd():
    """`int |F_crank-rod|^2 dt` on the free rigid slider-crank: d psi / d(spring stiffness, slider mass) by the
    adjoint, by automatic differentiation (forward mode, `_forward_mode`) and by central differences.
    Slow: the adjoint program compiles for 45 s on one core."""
    problem = fj.cases.rigid_slider_crank(0.2, driven=False)
    problem = problem.with_objective(fj.JointLoad(problem, "Revolute(crank,rod)", "force", 2))
    grad = fj.value_and_grad(problem, method=ADJOINT)[1]
    adjoint = np.array([grad.scene.forces[0].stiffness, grad.scene.bodies[2].data.mass])

    def with_parameters(p):
        return eqx.tree_at(lambda q: (q.scene.forces[0].stiffness, q.scene.bodies[2].data.mass), problem, (p[0], p[1]))

    # At the paper's forward tolerances, as value_and_grad(problem, method="autodiff") solves.
    autodiff = _forward_mode(lambda p: fj.simulate(with_parameters(p), rtol=1e-10, atol=1e-12,
                                                   adjoint=diffrax.ForwardMode()).psi, [K, M3])
    np.testing.assert_allclose(adjoint, autodiff, rtol=ADJOINT_VS_AUTODIFF, err_msg="adjoint vs autodiff")

    def psi(k):  # from the adjoint program compiled above (its forward solve), not a forward program of its own
        changed = eqx.tree_at(lambda q: q.scene.forces[0].stiffness, problem, jnp.asarray(k))
        return float(fj.value_and_grad(changed, method=ADJOINT)[0])

    h = K * 1e-4
    fd = (psi(K + h) - psi(K - h)) / (2 * h)
    np.testing.assert_allclose(fd, autodiff[0], rtol=FINITE_DIFFERENCES, err_msg="central differences vs autodiff")


@pytest.mark.slow
def test_driving_torque_design_gradient_adjoint_autodiff_fd():
    """`int tau^2 dt` of the crank pin on the flexible family rod: d psi / dx by the adjoint, by automatic
    differentiation (forward mode) and, along one direction, by central differences. Slow: the adjoint's compile."""
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    case = case.with_objective(fj.JointLoad(case, "CrankPin(rod)", "torque", 2))
    x = case.initial_design(0.5)
    adjoint = np.asarray(fj.value_and_grad(case, x, method=ADJOINT)[1])
    # Automatic differentiation in forward mode along the design's entries (`_forward_mode`), at the paper's tolerances.
    autodiff = _forward_mode(lambda y: fj.simulate(case, y, rtol=1e-10, atol=1e-12, adjoint=diffrax.ForwardMode()).psi, x)
    # Bounds as above (measured 1.6e-8 with the adjoint at its default 1e-8).
    np.testing.assert_allclose(adjoint, autodiff, rtol=ADJOINT_VS_AUTODIFF, err_msg="adjoint vs autodiff")
    v = np.linspace(1.0, -1.0, x.size)
    h = 1e-4
    # psi from the adjoint program compiled above (its forward solve), not a forward program of its own
    fd = (float(fj.value_and_grad(case, x + h * v, method=ADJOINT)[0])
          - float(fj.value_and_grad(case, x - h * v, method=ADJOINT)[0])) / (2 * h)
    assert abs(fd - autodiff @ v) <= FINITE_DIFFERENCES * np.abs(autodiff) @ np.abs(v), "central differences vs autodiff"
