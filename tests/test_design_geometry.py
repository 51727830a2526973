"""Design domains of other shapes: a plate with a hole (converged frequency) and a gmsh link with pin holes."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_close_relative

import ffr_jax._design as fd

# --- a plate with a hole: Richardson extrapolation -------------------------------------------------

# Steel square plate 1 m x 1 m x 10 mm with a central hole of radius 0.2 m, outer edges clamped,
# in-plane vibration. The O-grid meshes n = 8, 16, 32 are nested; both elements converge with
# order 2 (the straight-edged hole adds an O(h^2) geometry error of the same order).
PLATE = dict(side=1.0, radius=0.2)
E, RHO, NU, T = 2.1e11, 7850.0, 0.3, 0.01
MESHES = (8, 16, 32)


def _plate_frequency(element, n):
    plate = fd.plate_with_hole(PLATE["side"], PLATE["radius"], n)
    model = fd.FEModel(plate.mesh, element, T, NU)
    layout = fd.ModalReduction(2, fd.Clamped(plate.outer_nodes)).layout(plate.mesh)
    ones = jnp.ones(plate.mesh.n_elements)
    lam, _ = fd.LanczosModes().solve(model, E * ones, RHO * ones, layout, 2)
    return float(np.sqrt(lam[0]) / (2 * np.pi))


def test_plate_with_hole_frequency_converges_to_its_richardson_limit():
    """First in-plane frequency (a double mode of the symmetric plate), Q4 and QM6.

    Checks: the observed order `log2((f_h - f_h/2) / (f_h/2 - f_h/4))` is 2 (1.8..2.2: the
    asymptotic range begins at n = 8, measured 1.89 and 1.93); the two elements, with different
    discretisation errors, extrapolate to one limit `f_h/4 + (f_h/4 - f_h/2) / (2^p - 1)` within
    1e-4 — what Richardson leaves is the next-order term, which moves the limits by 1.7e-5 (Q4)
    and 7e-6 (QM6) from meshes (8, 16, 32) to (16, 32, 64), and the two limits differ by 1.1e-5;
    the finest QM6 mesh is within 0.1 % of its limit (measured 1.5e-4). Limit: 3769.47 Hz
    (benchmarks/RESULTS.md, "Elements: bending of a slender beam, plate with a hole").
    """
    limits = {}
    for element in (fd.Q4(), fd.QM6()):
        f = np.array([_plate_frequency(element, n) for n in MESHES])
        order = np.log2((f[0] - f[1]) / (f[1] - f[2]))
        name = type(element).__name__
        assert 1.8 < order < 2.2, f"{name}: observed order {order:.3f}, expected 2 ({f})"
        limits[name] = f[2] + (f[2] - f[1]) / (2**order - 1)
        if name == "QM6":
            np.testing.assert_allclose(f[2], limits[name], rtol=1e-3, err_msg="QM6 on the 32-mesh vs its limit")
    np.testing.assert_allclose(limits["QM6"], limits["Q4"], rtol=1e-4, err_msg="Q4 and QM6 extrapolate to one limit")


# --- the link with two pin holes (gmsh) -------------------------------------------------------------


@pytest.fixture(scope="module")
def link():
    pytest.importorskip("gmsh")
    return fd.link_with_holes(length=0.2, width=0.05, hole_radius=0.008, rim_width=0.005, mesh_size=0.004)


def _link_body(link):
    model = fd.FEModel(link.mesh, fd.QM6(), 0.005, 0.3)
    reduction = fd.ModalReduction(4, fd.Clamped(link.rims[0]), interfaces=(fd.Interface(link.rims[1], rigid=True),),
                                  solver=fd.LanczosModes())
    return fd.DesignedBody(model, link.domain, fd.SIMP(), reduction, (link.rims[0], link.rims[1]))


def test_link_mesh_is_valid_and_its_rims_are_passive(link, tmp_path):
    mesh, domain = link.mesh, link.domain
    assert mesh.n_elements > 500 and np.all(mesh.element_areas() > 0) and mesh.jacobian_ratios().min() > 0.05
    area = 0.2 * 0.05 + np.pi * 0.025**2 - 2 * np.pi * 0.008**2
    # A circle drawn as an n-gon loses pi R^2 (2 pi / n)^2 / 6 of its area: the two 14-gon holes
    # 1.2e-3 of the link's area (the link gains it), the rounded ends (about 39 sides per circle)
    # 0.7e-3 (the link loses it); |error| <= their sum, 2e-3 (measured +4.6e-4, their difference).
    np.testing.assert_allclose(mesh.element_areas().sum(), area, rtol=2e-3, err_msg="meshed area")
    for rim, centre in zip(link.rims, link.centres):
        assert len(rim) >= 8
        np.testing.assert_allclose(np.linalg.norm(mesh.nodes[list(rim)] - centre, axis=1), 0.008, rtol=1e-6)
        np.testing.assert_allclose(mesh.nodes[list(rim)].mean(0), centre, atol=1e-3 * 0.008,
                                   err_msg="rim centroid is the pin centre")
    # Passive rims: solid, no design variable, no dependence on the design.
    roles = domain.role_array()
    assert np.all(roles[link.rim_elements] == fd.SOLID) and np.all(roles[~link.rim_elements] == fd.DESIGN)
    assert domain.n_design == mesh.n_elements - link.rim_elements.sum()
    assert not np.any(np.isin(np.asarray(domain.design_elements), np.flatnonzero(link.rim_elements)))
    x = jnp.asarray(np.random.default_rng(0).uniform(0.1, 1.0, domain.n_design))
    _, pullback = jax.vjp(lambda x: domain.element_densities(x, 0.01), x)
    xe = domain.element_densities(x, 0.01)
    assert np.all(np.asarray(xe)[link.rim_elements] == 1.0), "rim elements are solid whatever the design"
    (g,) = pullback(jnp.asarray(link.rim_elements, dtype=float))
    assert np.all(np.asarray(g) == 0.0), "no design variable reaches a rim element"
    # The mesh survives a gmsh file round trip with its roles as cell data.
    path = str(tmp_path / "link.msh")
    tags = {"gmsh:physical": roles.astype(np.int64) + 1, "gmsh:geometrical": np.ones(mesh.n_elements, int)}
    fd.write_mesh(path, mesh, tags, file_format="gmsh22")
    import meshio

    read = meshio.read(path)
    assert fd.from_meshio(read) == mesh
    np.testing.assert_array_equal(fd.quad_cell_data(read)["gmsh:physical"] - 1, roles)


def test_link_modes_with_interfaces_at_the_pin_holes(link):
    """Clamped at hole A, a rigid interface at hole B (3 static modes), 4 eigenmodes; markers at the
    pin centres; the gradient of a body-data invariant against central differences."""
    body = _link_body(link)
    x = body.initial_design(0.5)

    @eqx.filter_jit
    def stage(body, x):
        def invariant(x):
            d = body.body_data(x)
            mq_inv = jnp.linalg.inv(d.modal_mass)
            return jnp.trace(mq_inv @ d.modal_stiffness) * 1e-8 + jnp.sum(d.modal_moment @ mq_inv @ d.modal_moment.T), d

        (value, data), grad = jax.value_and_grad(invariant, has_aux=True)(x)
        return body.modes(x), data, value, grad

    basis, data, _, g = stage(body, x)
    assert basis.n_static == 3 and basis.modes.shape == (link.mesh.n_dof, 7)
    assert np.all(np.diff(np.asarray(basis.eigenvalues)) > 0) and basis.eigenvalues[0] > 0
    np.testing.assert_allclose(data.marker_positions, link.centres, atol=1e-3 * 0.008, err_msg="markers at pin centres")
    assert np.all(np.asarray(data.marker_modes[0]) == 0.0), "the clamped hole has no elastic displacement"
    np.testing.assert_allclose(data.marker_modes[1][:, 4:], np.eye(2, 3), atol=1e-12,
                               err_msg="hole B's centre follows the translations of its rigid interface")
    assert g.shape == (link.domain.n_design,) and np.all(np.isfinite(np.asarray(g)))
    step = 1e-4  # central differences: truncation step^2 ~ 1e-8, round-off eps / step ~ 1e-12 relative
    for e in np.argsort(-np.abs(np.asarray(g)))[:2]:
        unit = jnp.zeros(body.n_design).at[e].set(step)
        fd_ = (stage(body, x + unit)[2] - stage(body, x - unit)[2]) / (2 * step)
        assert_close_relative(g[e], fd_, 1e-5, f"d invariant / d x_{e} vs central differences")
