"""Spatial body data of a solid FE body (`fj.solid_body_data`, issue 27): a planar body embedded at `z = 0` gives the
planar lift's data (an independent route: 3-D fields, the `m_s ⊗ I_3` mass, the 3 x 3 rigid fit), and a box gives
its analytic mass, moments and the exact rotation of a rigid turn.

Tolerance: both sides are exact for the FE model, so they differ by round-off only: ~1e-16 per operation times the
few hundred terms of a sum over the nodes of these small meshes (and one 3 x 3 inverse, condition number < 1e2):
1e-12 of each quantity's largest entry.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj

ROUNDOFF = 1e-12
FIELDS = ("mass", "first_moment", "modal_moment", "second_moment", "second_moment_q", "second_moment_qq",
          "modal_mass", "modal_stiffness", "marker_positions", "marker_modes", "marker_rotations")


def _close(got, want, name):
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape, f"{name}: shape {got.shape} vs {want.shape}"
    err = np.max(np.abs(got - want)) if got.size else 0.0
    assert err <= ROUNDOFF * max(np.max(np.abs(want)), 1e-300), f"{name}: error {err:.3e}"


def _embed_dofs(v2, n_nodes):
    """Planar interleaved `(2 n, ...)` -> spatial `(3 n, ...)` with zero `z` components."""
    pairs = np.asarray(v2).reshape((n_nodes, 2) + np.shape(v2)[1:])
    return np.concatenate([pairs, np.zeros((n_nodes, 1) + pairs.shape[2:])], axis=1).reshape((3 * n_nodes,) +
                                                                                                pairs.shape[2:])


def test_planar_body_embedded_at_z0_equals_the_lift():
    """Nodes `(x, y, 0)`, `M = m_s ⊗ I_3`, `K` in the in-plane slots, modes with `u_z = 0`, the planar markers (one
    node each: the patch of elements): every field equals `fj.lifted_body_data` of the planar body."""
    body = fj.cases.rod_body(4, 2, 2)
    x = body.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(body.n_design, dtype=float))
    youngs, densities = body.element_values(x)
    k2, m2 = (np.asarray(a.todense()) for a in body.matrices(x))
    modes2 = np.asarray(body.reduction(body.model, youngs, densities).modes)
    n = body.model.mesh.n_nodes
    coords = np.concatenate([np.asarray(body.model.coordinates), np.zeros((n, 1))], axis=1)
    m_s = m2[0::2, 0::2]
    np.testing.assert_array_equal(m2[1::2, 1::2], m_s, err_msg="the planar mass matrix is m_s ⊗ I_2")
    m3 = np.kron(m_s, np.eye(3))
    k3 = _embed_dofs(_embed_dofs(k2, n).T, n).T

    @jax.jit
    def both(k2, m2, modes2, k3, m3, modes3):
        return (fj.lifted_body_data(body.model, k2, m2, modes2, body.markers),
                fj.solid_body_data(coords, k3, m3, modes3, body.markers, elements=body.model.mesh.elements))

    want, got = both(k2, m2, modes2, k3, m3, _embed_dofs(modes2, n))
    for name in FIELDS:
        _close(getattr(got, name), getattr(want, name), name)


@pytest.fixture(scope="module")
def box():
    """A `2 x 2 x 2` H8 box `[0, 0.3] x [-0.1, 0.1] x [-0.05, 0.05]` shifted by `offset`, density `rho`."""
    mesh = fj.box_grid(2, 2, 2, 0.3, 0.2, 0.1)
    offset = np.array([0.2, -0.1, 0.3])
    shifted = fj.SolidMesh(mesh.nodes + offset, mesh.elements)
    model = fj.SolidFEModel(shifted, fj.H8(), poisson=0.3)
    rho = 7800.0
    lo, hi = np.array([0.0, -0.1, -0.05]) + offset, np.array([0.3, 0.1, 0.05]) + offset
    return model, rho, lo, hi


def _linear_modes(c, rng):
    """Two linear fields `phi_k = A_k c + t_k` and their `(A_k, t_k)`: the moments of a linear field are those of
    the box's own moments (`sum_m phi = A s0 + m t`, ...), and trilinear hexahedra interpolate them exactly."""
    a, t = rng.normal(size=(2, 3, 3)), rng.normal(size=(2, 3))
    modes = np.stack([c @ a[k].T + t[k] for k in range(2)], axis=-1)  # (n, 3, 2)
    return modes.reshape(-1, 2), a, t


def test_box_moments_are_analytic(box):
    """`m = rho V`, `s0 = m c_G`, `C0 = rho int c c^T dV` (2x2x2 Gauss integrates the trilinear mass matrix's
    products of linear fields exactly), and for linear modes `S1`, `C1`, `C2`, `M_qq` from them; through `jax.jit`
    with the mass as a matrix-free operator (pure JAX)."""
    model, rho, lo, hi = box
    n = model.mesh.n_nodes
    c = np.asarray(model.coordinates)
    modes, a, t = _linear_modes(c, np.random.default_rng(0))
    markers = (int(np.argmin(np.sum((c - lo) ** 2, axis=1))),
               tuple(int(i) for i in np.flatnonzero(np.isclose(c[:, 0], hi[0]))))

    @jax.jit
    def data(model, densities, modes):
        return fj.solid_body_data(model.mesh.nodes, model.stiffness(jnp.ones(model.n_elements)),
                                  model.mass(densities), modes, markers, elements=model.mesh.elements)

    got = data(model, jnp.full(model.n_elements, rho), jnp.asarray(modes))
    volume = np.prod(hi - lo)
    mass = rho * volume
    first = mass * 0.5 * (lo + hi)
    # int_a^b x dx = (b^2 - a^2)/2, int_a^b x^2 dx = (b^3 - a^3)/3, per direction; off-diagonal: products of first.
    one = hi - lo
    lin = 0.5 * (hi**2 - lo**2)
    quad = (hi**3 - lo**3) / 3.0
    c0 = rho * np.array([[(quad[i] if i == j else lin[i] * lin[j]) * np.prod(one[[k for k in range(3) if k not in
                                                                                    (i, j)]]) for j in range(3)]
                         for i in range(3)])
    _close(got.mass, mass, "mass")
    _close(got.first_moment, first, "first moment")
    _close(got.second_moment, c0, "second moment C0")
    _close(got.modal_moment, np.stack([a[k] @ first + mass * t[k] for k in range(2)], axis=1), "modal moment S1")
    _close(got.second_moment_q, np.stack([c0 @ a[k].T + np.outer(first, t[k]) for k in range(2)]), "C1")
    c2 = np.array([[a[j] @ c0 @ a[k].T + np.outer(a[j] @ first, t[k]) + np.outer(t[j], a[k] @ first)
                    + mass * np.outer(t[j], t[k]) for k in range(2)] for j in range(2)])
    _close(got.second_moment_qq, c2, "C2")
    _close(got.modal_mass, np.trace(c2, axis1=2, axis2=3), "modal mass = tr C2")
    nodal = modes.reshape(n, 3, 2)
    _close(got.marker_positions, np.stack([c[list(np.atleast_1d(s))].mean(axis=0) for s in markers]), "positions")
    _close(got.marker_modes, np.stack([nodal[list(np.atleast_1d(s))].mean(axis=0) for s in markers]), "marker modes")


def test_marker_rotations_of_rigid_turns(box):
    """The rotation of the least-squares rigid fit is exact for a rigid field: `phi = w x (c - p)` gives `Psi = w`,
    a translation gives 0, at a one-node marker (patch of its elements), a face (its own nodes) and a line of nodes
    (collinear: the patch)."""
    model, rho, lo, hi = box
    c = np.asarray(model.coordinates)
    w = np.array([0.3, -1.1, 0.7])
    turn = np.cross(w, c - np.array([0.5, 0.2, -0.4]))
    modes = np.stack([turn.ravel(), np.tile([0.3, -0.7, 0.2], c.shape[0])], axis=1)
    corner = int(np.argmin(np.sum((c - lo) ** 2, axis=1)))
    face = tuple(int(i) for i in np.flatnonzero(np.isclose(c[:, 0], hi[0])))
    line = tuple(int(i) for i in np.flatnonzero(np.isclose(c[:, 0], lo[0]) & np.isclose(c[:, 1], lo[1])))
    markers = (corner, face, line)

    @jax.jit
    def data(model, modes):
        m = model.mass(jnp.full(model.n_elements, rho))
        return fj.solid_body_data(c, m, m, modes, markers, elements=model.mesh.elements)

    got = data(model, jnp.asarray(modes))
    psi = np.asarray(got.marker_rotations)
    np.testing.assert_allclose(psi[:, :, 0], np.tile(w, (3, 1)), rtol=0, atol=ROUNDOFF, err_msg="rigid turn")
    np.testing.assert_allclose(psi[:, :, 1], 0.0, rtol=0, atol=ROUNDOFF, err_msg="translation")


def test_collinear_marker_needs_elements(box):
    model, rho, lo, hi = box
    c = np.asarray(model.coordinates)
    m = model.mass(jnp.full(model.n_elements, rho))
    modes = jnp.ones((model.n_dof, 1))
    with pytest.raises(ValueError, match="on one line.*elements="):
        fj.solid_body_data(c, m, m, modes, (0,))
    with pytest.raises(ValueError, match="outside"):
        fj.solid_body_data(c, m, m, modes, ((0, c.shape[0]),), elements=model.mesh.elements)
    with pytest.raises(ValueError, match="modes must have shape"):
        fj.solid_body_data(c, m, m, jnp.ones((model.n_dof - 1, 1)), (0,), elements=model.mesh.elements)
