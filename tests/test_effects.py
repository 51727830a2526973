"""Effects a scene switches on (gravity, damping, geometric stiffening): physics when on, nothing when off.

"Off costs nothing" is shown on the traced program itself: a scene without an effect holds no
object of it, and the vector field traced for it has exactly as many primitive operations as the
same scene built with no effect at all (and strictly fewer than with the effect on), and fewer
flops in XLA's cost analysis of the compiled vector field.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax


def _count_equations(jaxpr) -> int:
    """Primitive operations of a jaxpr, sub-jaxprs (loops, conditionals, custom rules) included."""
    n = 0
    for eqn in jaxpr.eqns:
        n += 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, (list, tuple)) else (value,):
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    n += _count_equations(sub.jaxpr)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    n += _count_equations(sub)
    return n


def _vector_field(case, scene):
    y, z = case.model.split(case.y_r0)[0], case.model.split(case.z_r0)[0]
    return lambda s: case.model.vector_field(jnp.asarray(0.1), y, z, s)


def _trace_size(case, scene) -> int:
    return _count_equations(jax.make_jaxpr(_vector_field(case, scene))(scene).jaxpr)


def _flops(case, scene) -> float:
    analysis = jax.jit(_vector_field(case, scene)).lower(scene).compile().cost_analysis()
    analysis = analysis[0] if isinstance(analysis, (list, tuple)) else analysis
    return float(analysis["flops"])


@functools.cache
def _pendulum_cached(gravity: bool, damping_ratio):
    case = ffr_jax.cases.flexible_pendulum(8, 2, 3, t1=0.5, gravity=gravity, damping_ratio=damping_ratio)
    return case, eqx.filter_jit(case.scene)(case.initial_design(0.5))


def _pendulum(gravity: bool = True, damping_ratio=None):
    return _pendulum_cached(gravity, damping_ratio)


def _effect_types(scene):
    return {type(f).__name__ for f in scene.forces}


# --- off costs nothing ---------------------------------------------------------------------------
def test_effects_that_are_off_are_not_traced():
    base_case, base = _pendulum(gravity=False)
    assert _effect_types(base) == set(), "a pendulum without gravity and damping holds no effect"
    n_base = _trace_size(base_case, base)
    # The same scene assembled by hand with an explicitly empty effect list traces identically.
    bare = ffr_jax.Scene(bodies=base.bodies, constraints=base.constraints, forces=())
    assert _trace_size(base_case, bare) == n_base
    for kwargs, effect in [({"gravity": True}, "Gravity"), ({"gravity": False, "damping_ratio": 0.02}, "ModalDamping")]:
        case, scene = _pendulum(**kwargs)
        assert _effect_types(scene) == {effect}
        n_on = _trace_size(case, scene)
        assert n_on > n_base, f"{effect} on should add operations ({n_on} vs {n_base})"
    # Rayleigh damping with zero coefficients is *on* (and costs), so "off" must mean absent.
    zero_rayleigh = ffr_jax.Scene(bodies=base.bodies, constraints=base.constraints,
                                  forces=(ffr_jax.RayleighDamping(0, 0.0, 0.0),))
    assert _trace_size(base_case, zero_rayleigh) > n_base


def test_effects_that_are_off_cost_no_flops():
    base_case, base = _pendulum(gravity=False)
    grav_case, grav = _pendulum(gravity=True)
    bare = ffr_jax.Scene(bodies=base.bodies, constraints=base.constraints, forces=())
    assert _flops(base_case, base) == _flops(base_case, bare)
    assert _flops(base_case, base) < _flops(grav_case, grav)


def test_geometric_stiffening_off_is_not_traced():
    """Without stiffening neither the vector field nor the design map `x -> p(x)` computes `K_geo`."""
    off = ffr_jax.cases.spinning_beam(8, 2, 3, t1=0.1, stiffening=False)
    on = ffr_jax.cases.spinning_beam(8, 2, 3, t1=0.1, stiffening=True)
    x = off.initial_design(0.5)
    assert _effect_types(off.scene(x)) == set()
    assert _effect_types(on.scene(x)) == {"GeometricStiffening"}
    assert _trace_size(off, off.scene(x)) < _trace_size(on, on.scene(x))
    design_map = lambda case: _count_equations(jax.make_jaxpr(case.scene)(x).jaxpr)  # noqa: E731
    plain = ffr_jax.cases.slider_crank(8, 2, 3, t1=0.1)
    assert design_map(off) == design_map(plain), "x -> p(x) without stiffening is the plain body-data map"
    assert design_map(off) < design_map(on)


# --- physics when on ------------------------------------------------------------------------------
@functools.cache
def _pendulum_run(gravity: bool, damping_ratio):
    case, scene = _pendulum(gravity=gravity, damping_ratio=damping_ratio)
    ts = jnp.linspace(case.t0, case.t1, 26)
    traj = eqx.filter_jit(ffr_jax.simulate)(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, rtol=1e-10,
                                            atol=1e-12, ts=ts)
    states = jax.jit(jax.vmap(lambda t, y, z: case.model.state(t, y, z, scene)))(traj.ts, traj.ys, traj.zs)
    return case, scene, traj, states


def test_gravity_off_leaves_the_released_pendulum_at_rest():
    """Released from rest at -45 deg: no acceleration without gravity; with it, the rod swings down."""
    for gravity in (False, True):
        case, scene = _pendulum(gravity=gravity)
        y_r, z_r = case.y_r0, case.z_r0
        zdot = jax.jit(lambda t, y_r, z_r: case.model.accelerations(t, y_r, z_r, scene))(jnp.asarray(0.0), y_r, z_r)
        if not gravity:
            np.testing.assert_array_equal(zdot, 0.0)
            continue
        # Second derivation at rest (no velocity terms): Mbar zdot = -J^T dV/dy_r, with J = dy_r/dy and
        # the potential V (gravity + strain energy) differentiated by JAX.
        @jax.jit
        def at_rest(y_r):
            t = jnp.asarray(0.0)
            y = case.model.split(y_r)[0]
            jac = jax.jacfwd(lambda y: case.model.positions(t, y, scene))(y)
            grad_v = jax.grad(lambda y_r: scene.potential_energy(t, y_r))(y_r)
            return jnp.linalg.solve(jac.T @ scene.mass_matrix(y_r) @ jac, -jac.T @ grad_v)

        expected = at_rest(y_r)
        np.testing.assert_allclose(zdot, expected, rtol=1e-10, atol=1e-12 * float(jnp.max(jnp.abs(expected))))
        theta_index = case.model.partition.independent.index(2)
        assert float(zdot[theta_index]) < 0.0, "released at -45 deg, the rod swings down"


def test_modal_damping_dissipates_exactly_its_power():
    """With gravity and modal damping: `d(T + V)/dt = z_r . Q_damping <= 0` along the motion, and energy drops."""
    case, scene, traj, (y_r, z_r) = _pendulum_run(True, 0.05)
    model = case.model
    damping = next(f for f in scene.forces if isinstance(f, ffr_jax.ModalDamping))

    def energy(t, y_r, z_r):
        return scene.kinetic_energy(y_r, z_r) + scene.potential_energy(t, y_r)

    def rates(t, y, z, y_r, z_r):
        zdot = model.accelerations(t, y_r, z_r, scene)
        tangent = (jnp.ones_like(t), z, zdot)
        de_dt = jax.jvp(lambda tt, yy, zz: energy(tt, *model.state(tt, yy, zz, scene)), (t, y, z), tangent)[1]
        dv_dt = jax.jvp(lambda tt, yy, zz: scene.potential_energy(tt, model.state(tt, yy, zz, scene)[0]),
                        (t, y, z), tangent)[1]
        return de_dt, z_r @ damping.generalized_force(t, y_r, z_r, scene), dv_dt

    de_dt, power, dv_dt = jax.jit(jax.vmap(rates))(traj.ts, traj.ys, traj.zs, y_r, z_r)
    assert float(jnp.max(power)) <= 0.0, "damping must not do positive work"
    # d(T + V)/dt is the small difference of the kinetic and potential rates (gravity's power, ~5e5
    # times the damping power here): equal to the damping power in exact arithmetic, so up to the
    # round-off of those rates, eps times their size times the operations (measured 2, allowed 100).
    roundoff = 100 * np.finfo(float).eps * float(jnp.max(jnp.abs(dv_dt)))
    np.testing.assert_allclose(de_dt, power, rtol=0, atol=roundoff, err_msg="d(T + V)/dt vs damping power")
    e = jax.jit(jax.vmap(energy))(traj.ts, y_r, z_r)
    assert float(e[-1]) < float(e[0]), "a damped pendulum loses energy"


def _dominant_frequency(ts, signal):
    """Oscillation frequency from the mean period between upward zero crossings (signal detrended)."""
    s = np.asarray(signal) - np.mean(np.asarray(signal))
    t = np.asarray(ts)
    up = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    crossings = t[up] - s[up] * (t[up + 1] - t[up]) / (s[up + 1] - s[up])
    assert crossings.size >= 3, "too few oscillations to measure a frequency"
    return 1.0 / np.mean(np.diff(crossings))


@pytest.mark.parametrize("speed", [150.0])
def test_geometric_stiffening_stiffens_a_spinning_beam(speed):
    """Spinning at `Omega`, the first bending mode oscillates faster with stiffening than without.

    Southwell: `omega^2 = omega_0^2 + alpha Omega^2` with `alpha > 0` for the stiffened beam; the
    modal FFR model without stiffening softens instead (`omega < omega_0`, Kane et al. 1987).
    """
    freqs = {}
    for stiffening in (False, True):
        case = ffr_jax.cases.spinning_beam(8, 2, 3, t1=0.15, speed=speed, stiffening=stiffening)
        x = case.initial_design(0.5)
        scene = case.scene(x)
        ts = jnp.linspace(case.t0, case.t1, 600)
        traj = eqx.filter_jit(ffr_jax.simulate)(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0,
                                                rtol=1e-9, atol=1e-12, ts=ts)
        q1 = traj.ys[:, 0]
        freqs[stiffening] = _dominant_frequency(traj.ts, q1)
        assert np.all(np.isfinite(np.asarray(traj.ys)))
        f0 = float(case.frequencies(x)[0])
    assert freqs[True] > f0 > freqs[False], f"stiffened {freqs[True]:.2f} Hz, at rest {f0:.2f} Hz, unstiffened {freqs[False]:.2f} Hz"
