"""The design chain in 3D (issue 27): densities on a solid mesh, passive regions by physical-group name, the density
filter and volume constraint on solid meshes, supports and markers from named groups, and the derivative of the
spatial body data in the densities.

Default tests use a 3 x 2 x 2 hexahedral block with in-memory gmsh-style groups (no gmsh run, nothing compiled); the
slow ones mesh the worked example's connecting rod with gmsh at its coarsest (`size=0.02`, one layer: 160 H8, 1218
degrees of freedom) and differentiate its body data.
"""

import jax
import jax.numpy as jnp
import meshio
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._design.domain import DESIGN, SOLID

HUB, WEB, END = 1, 2, 3


def _block():
    """`box_grid(3, 2, 2, 3, 2, 2)` (unit cubes) with groups: volume "hub" (elements with centroid x < 1), volume
    "web" (the rest), surface "end" (the faces on x = 0)."""
    mesh = fj.box_grid(3, 2, 2, 3.0, 2.0, 2.0)
    centroids = mesh.nodes[mesh.elements].mean(axis=1)
    tags = np.where(centroids[:, 0] < 1.0, HUB, WEB)
    end = [f for f in fj._design.solid_groups.boundary_faces(mesh) if np.all(mesh.nodes[f, 0] == 0.0)]
    end = np.array([[f[0], f[1], f[3], f[2]] for f in end])  # sorted corners -> a cyclic order of a unit square
    field = {"hub": np.array([HUB, 3]), "web": np.array([WEB, 3]), "end": np.array([END, 2])}
    m = meshio.Mesh(mesh.nodes, [("hexahedron", mesh.elements), ("quad", end)],
                    cell_data={"gmsh:physical": [tags, np.full(len(end), END)]}, field_data=field)
    return fj.solid_groups_from_meshio(m), tags


@pytest.fixture(scope="module")
def block():
    return _block()


def test_passive_regions_by_name_carry_no_design_variable(block):
    """The hub's elements are passive solid: no design variable, density 1 whatever the design."""
    groups, tags = block
    domain = fj.SolidDesignDomain.from_groups(groups, solid=("hub",))
    assert domain.n_design == np.count_nonzero(tags == WEB)
    np.testing.assert_array_equal(np.asarray(domain.design_elements), np.flatnonzero(tags == WEB))
    x = jnp.linspace(0.1, 0.9, domain.n_design)
    xe = np.asarray(domain.element_densities(x, 0.01))
    np.testing.assert_array_equal(xe[tags == HUB], 1.0)
    np.testing.assert_array_equal(xe[tags == WEB], np.asarray(x))
    void = fj.SolidDesignDomain.from_groups(groups, void=("hub",))
    np.testing.assert_array_equal(np.asarray(void.element_densities(x, 0.01))[tags == HUB], 0.01)


def test_bad_names_and_directions_are_errors(block):
    groups, _ = block
    with pytest.raises(ValueError, match="no physical group named 'hubs'"):
        fj.SolidDesignDomain.from_groups(groups, solid=("hubs",))
    with pytest.raises(ValueError, match="'end' has dimension 2"):
        fj.SolidDesignDomain.from_groups(groups, solid=("end",))
    with pytest.raises(ValueError, match="no physical group named 'bore'"):
        fj.solid_designed_body(groups, 2, markers=("bore",), supports={"end": "xyz"})
    with pytest.raises(ValueError, match="string of 'x', 'y', 'z'"):
        fj.solid_designed_body(groups, 2, markers=("end",), supports={"end": "xw"})
    with pytest.raises(ValueError, match="no design element"):
        fj.SolidDesignDomain.from_groups(groups, solid=("hub", "web"))


def test_supports_and_markers_from_groups(block):
    groups, tags = block
    body = fj.solid_designed_body(groups, 2, markers=("end",), supports={"end": "xz"}, solid=("hub",))
    end = np.flatnonzero(groups.mesh.nodes[:, 0] == 0.0)
    assert body.markers == (tuple(int(n) for n in end),)
    assert body.fixed_dofs == tuple(sorted([3 * int(n) for n in end] + [3 * int(n) + 2 for n in end]))
    assert body.n_design == np.count_nonzero(tags == WEB)


def test_density_filter_on_a_solid_mesh(block):
    """On unit cubes, `r = 1.5` m (`scale=(1, 1, 1)`) reaches the face (d = 1) and edge (d = sqrt 2 = 1.41)
    neighbours, not the corner ones (d = sqrt 3 = 1.73): the cone weights `1.5 - d` are exact, rows sum to one; and
    the volume constraint's weights give the volume fraction of the filtered densities (`mean(c x) = mean(H x)` on
    equal volumes). Round-off: sums of a few terms of size 1, 1e-14."""
    groups, _ = block
    body = fj.solid_designed_body(groups, 2, markers=("end",), supports={"end": "xyz"})
    filt = fj.DensityFilter(body, 1.5, scale=(1.0, 1.0, 1.0))
    h = np.asarray(filt.matrix())
    centres = body.domain.design_centroids()
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    cone = np.where(d < 1.5, 1.5 - d, 0.0)
    np.testing.assert_allclose(h, cone / cone.sum(axis=1, keepdims=True), rtol=0, atol=1e-14)
    x = jnp.asarray(np.random.default_rng(0).uniform(0.1, 1.0, body.n_design))
    constraint = fj.VolumeConstraint(0.5, filter=filt)
    np.testing.assert_allclose(float(jnp.mean(constraint.weights * x)), float(jnp.mean(filt(x))), rtol=1e-14)
    with pytest.raises(ValueError, match="3 positive lengths"):
        fj.DensityFilter(body, 1.5, scale=(1.0, 1.0))


# --- the connecting rod (gmsh) -------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rod():
    pytest.importorskip("gmsh")
    body = fj.cases.connecting_rod(0.02, 1, 2).body
    x = body.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(body.n_design, dtype=float))
    return body, x


def _invariants(body, x):
    """A scalar of the body data that does not depend on the modes' signs (nor on rotations within the retained
    set): mass, moments, `sum lam`, and sums of squares over the modes; each term of order 1."""
    d = body.body_data(x)
    return (d.mass + jnp.sum(d.first_moment) * 10 + jnp.trace(d.second_moment) * 100
            + jnp.trace(d.modal_stiffness) / 1e7 + jnp.sum(d.modal_moment ** 2) + jnp.sum(d.marker_modes ** 2)
            + jnp.sum(d.marker_rotations ** 2) * 1e-3 + jnp.trace(d.second_moment_qq.sum(axis=(2, 3))))


@pytest.mark.slow
def test_connecting_rod_groups_and_markers(rod):
    """Hubs passive, web designed; markers at the bores' centres (gmsh spaces a circle's nodes evenly and the
    layers are symmetric about z = 0, so the centroid is the centre to round-off of the coordinates, 1e-15 m)."""
    body, x = rod
    roles = np.asarray(body.domain.roles)
    assert body.n_design == np.count_nonzero(roles == DESIGN) and np.all(roles[roles != DESIGN] == SOLID)
    positions = np.stack([body.mesh.nodes[list(m)].mean(axis=0) for m in body.markers])
    np.testing.assert_allclose(positions, [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]], rtol=0, atol=1e-12)


@pytest.mark.slow
def test_body_data_design_derivative_matches_central_differences(rod):
    """The reverse-mode gradient of an invariant of the body data equals central differences along a random
    direction of the densities and along two single densities (eager: compiling the chain costs more than running
    it on this small part).

    Central differences with `h = 1e-4` (densities ~0.5): truncation `h^2 g''' / 6`, O(h^2) (measured at
    `h = 1e-3`: 4e-5 of the derivative on a rod of this family, so ~4e-7 at 1e-4), round-off `eps |g| / h`
    amplified by the eigen-solution's condition `lam_max / lam_1 ~ 1e6` (thickness modes of the coarse layer): ~1e-6 of `|g|`. A 1e-5 bound of the
    larger of the derivative and `|g|` covers both; a missing or wrong term (a mass derivative, a marker
    rotation's) changes the derivative at the percent level."""
    body, x = rod
    value, grad = jax.value_and_grad(_invariants, argnums=1)(body, x)
    rng = np.random.default_rng(3)
    direction = jnp.asarray(rng.uniform(-1.0, 1.0, body.n_design))
    h = 1e-4
    singles = [int(np.argmax(np.abs(grad))), int(rng.integers(body.n_design))]
    for name, d in [("random direction", direction)] + [(f"density {i}", jnp.zeros(body.n_design).at[i].set(1.0))
                                                        for i in singles]:
        fd = float(_invariants(body, x + h * d) - _invariants(body, x - h * d)) / (2 * h)
        got = float(grad @ d)
        assert abs(got - fd) <= 1e-5 * max(abs(fd), abs(float(value))), f"{name}: gradient {got}, central {fd}"


@pytest.mark.slow
def test_case_design_and_mesh_of_a_solid_case():
    """`case.design` / `case.mesh` (the one designed body and its mesh) work for a solid case under the suite's
    runtime type checks too (they were annotated for planar bodies only, and a solid case raised there)."""
    pytest.importorskip("gmsh")
    case = fj.cases.connecting_rod_slider_crank(0.02, 1, 2)
    assert isinstance(case.design, fj.SolidDesignedBody) and case.design is case.design_map.only
    assert isinstance(case.mesh, fj.SolidMesh)
