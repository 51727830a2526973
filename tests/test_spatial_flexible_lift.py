"""A planar FE body lifted into space (issue 26): its spatial body data hold the planar data, and in a planar motion
its spatial equations of motion are the planar ones.

Both sides are the same quadratic forms of the same `M`, `K` and modes, summed in another order: they agree to
round-off, ~1e-15 relative per operation times the few hundred operations of a sum over the nodes of the small rod.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._dynamics._body_dynamics import body_inertia_and_elastic_forces, body_mass_matrix
from ffr_jax._spatial import _flexible_body as flex
from ffr_jax._spatial._lift import designed_body_data

ROUNDOFF = 1e-12


@pytest.fixture(scope="module")
def rod():
    body = fj.cases.rod_body(4, 2, 2)
    x = body.initial_design(0.7)

    @jax.jit
    def both(x):
        return body.body_data(x), designed_body_data(body, x)

    planar, spatial = both(x)
    return planar, spatial, jax.tree.map(np.asarray, (planar, spatial))


def _close(got, want, name):
    got, want = np.asarray(got), np.asarray(want)
    assert np.max(np.abs(got - want)) <= ROUNDOFF * max(np.max(np.abs(want)), 1e-300), name


def test_lifted_data_hold_the_planar_data(rod):
    """`m`, `s0`, `S1`, `J0 = tr C0`, `j1 = tr C1`, `G0 = ax_z(C1)`, `G = ax_z(C2)`, `M_qq = tr C2` (the mass matrix
    is `m_s ⊗ I_2`), `K_qq`, markers; nothing out of the plane."""
    planar, spatial = rod[2]
    _close(spatial.mass, planar.mass, "mass")
    _close(spatial.first_moment, np.append(planar.first_moment, 0.0), "first moment")
    _close(spatial.modal_moment[:2], planar.modal_moment, "modal moment")
    _close(np.trace(spatial.second_moment), planar.inertia, "polar inertia J0")
    _close(np.trace(spatial.second_moment_q, axis1=1, axis2=2), planar.inertia_q, "j1")
    _close((spatial.second_moment_q[:, 0, 1] - spatial.second_moment_q[:, 1, 0]), planar.coupling_0, "coupling G0")
    _close((spatial.second_moment_qq[..., 0, 1] - spatial.second_moment_qq[..., 1, 0]).T, planar.coupling, "coupling G")
    _close(np.trace(spatial.second_moment_qq, axis1=2, axis2=3), planar.modal_mass, "modal mass = tr C2")
    _close(spatial.modal_mass, planar.modal_mass, "modal mass")
    _close(spatial.modal_stiffness, planar.modal_stiffness, "modal stiffness")
    _close(spatial.marker_positions[:, :2], planar.marker_positions, "marker positions")
    _close(spatial.marker_modes[:, :2], planar.marker_modes, "marker modes")
    out_of_plane = {"first moment": spatial.first_moment[2], "modal moment": spatial.modal_moment[2],
                    "marker positions": spatial.marker_positions[:, 2], "marker modes": spatial.marker_modes[:, 2],
                    "second moments": np.concatenate([spatial.second_moment[2], spatial.second_moment_q[:, 2].ravel(),
                                                       spatial.second_moment_qq[..., 2, :].ravel()])}
    for name, value in out_of_plane.items():
        assert np.all(np.asarray(value) == 0.0), f"{name} out of the plane"
    assert np.all(np.asarray(spatial.marker_rotations)[:, :2] == 0.0), "in-plane modes rotate about z only"


def _embed(y):
    """Planar `(R_x, R_y, theta, q)` -> spatial `(R, p, q)` with `p` the turn by `theta` about `z`."""
    half = 0.5 * y[2]
    zero = jnp.zeros_like(half)
    return jnp.concatenate([y[:2], zero[None], jnp.stack([jnp.cos(half), zero, zero, jnp.sin(half)]), y[3:]])


@pytest.mark.slow  # ~2 s (one more compiled program)
def test_planar_motion_of_the_lifted_body_is_the_planar_motion(rod):
    """On the embedded planar coordinates (`y_sp = E(y)`, `T = dE/dy`, `gamma = d(T ydot)/dt`) the spatial
    equations give `T^T M_sp T = M_pl` and `T^T (f_sp - M_sp gamma) = f_pl`."""
    planar, spatial, _ = rod
    rng = np.random.default_rng(3)
    y = jnp.asarray(np.concatenate([rng.normal(size=3), 1e-3 * rng.normal(size=2)]))
    z = jnp.asarray(np.concatenate([rng.normal(size=3), rng.normal(size=2)]))

    @jax.jit
    def both(planar, spatial, y, z):
        t = jax.jacfwd(_embed)(y)
        gamma = jax.jvp(lambda yy: jax.jvp(_embed, (yy,), (z,))[1], (y,), (z,))[1]
        y_sp, z_sp = _embed(y), t @ z
        m_sp = flex.mass_matrix(spatial, y_sp)
        f_sp = flex.inertia_and_elastic_forces(spatial, y_sp, z_sp)
        return (t.T @ m_sp @ t, body_mass_matrix(planar, y),
                t.T @ (f_sp - m_sp @ gamma), body_inertia_and_elastic_forces(planar, y, z))

    m_got, m_want, f_got, f_want = both(planar, spatial, y, z)
    _close(m_got, m_want, "mass matrix")
    _close(f_got, f_want, "forces")


def test_marker_rotations_of_rigid_fields():
    """The elastic rotation at a marker is the rotation of the least-squares rigid fit of its patch: exactly 1 for
    the field of an infinitesimal turn about `z` (`phi_n = z x c_n`), exactly 0 for a translation, at a one-node
    marker (patch of elements) and a node-set marker alike (round-off of a sum over a few nodes)."""
    body = fj.cases.rod_body(4, 2, 2)
    model = body.model
    c = np.asarray(model.coordinates)
    turn = np.stack([-c[:, 1], c[:, 0]], axis=1).ravel()
    shift = np.tile([0.3, -0.7], c.shape[0])
    modes = jnp.asarray(np.stack([turn, shift], axis=1))
    _, m = body.matrices(body.initial_design(0.5))
    markers = (body.markers[0], (body.markers[1], body.markers[1] - 1))
    k = jnp.eye(model.n_dof)  # any positive definite stiffness (a rigid field's own is zero up to round-off)
    psi = np.asarray(fj.lifted_body_data(model, k, m, modes, markers).marker_rotations)
    np.testing.assert_allclose(psi[:, 2, 0], 1.0, rtol=0, atol=ROUNDOFF, err_msg="rotation of a rigid turn")
    np.testing.assert_allclose(psi[:, 2, 1], 0.0, rtol=0, atol=ROUNDOFF, err_msg="rotation of a translation")
    assert np.all(psi[:, :2] == 0.0), "in-plane fields rotate about z only"
