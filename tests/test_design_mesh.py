"""Quad meshes: numbering of the structured grid, meshio round trip, element checks, identity, roles."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax._design as fd


def _square_patch():
    """A 2 x 2 patch of unit squares (9 nodes, 4 counter-clockwise elements)."""
    nodes = np.array([[x, y] for y in (0.0, 1.0, 2.0) for x in (0.0, 1.0, 2.0)])
    elements = np.array([[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]])
    return nodes, elements


# --- the structured grid reproduces the rod ---------------------------------------------------


@pytest.mark.parametrize("nx, ny", [(5, 4), (100, 6)])
def test_structured_grid_numbering_is_the_documented_layout(nx, ny):
    """REFERENCE_CASE §1: node `(i, j)` at `(i L / nx, -h/2 + j h / ny)` with index `i (ny + 1) + j`;
    element `(i, j)` with index `j nx + i` and nodes `(i, j), (i+1, j), (i+1, j+1), (i, j+1)`."""
    length, height = 2.0, 0.4
    mesh = fd.structured_grid(nx, ny, length, height)
    assert (mesh.nx, mesh.ny, mesh.dx, mesh.dy) == (nx, ny, length / nx, height / ny)
    i, j = np.divmod(np.arange(mesh.n_nodes), ny + 1)
    np.testing.assert_allclose(mesh.nodes, np.stack([i * length / nx, -height / 2 + j * height / ny], 1), rtol=0,
                               atol=1e-15, err_msg="node coordinates")
    ei, ej = np.arange(mesh.n_elements) % nx, np.arange(mesh.n_elements) // nx
    corners = np.stack([mesh.node(ei, ej), mesh.node(ei + 1, ej), mesh.node(ei + 1, ej + 1), mesh.node(ei, ej + 1)], 1)
    np.testing.assert_array_equal(mesh.elements, corners, err_msg="element nodes, counter-clockwise")
    np.testing.assert_array_equal(mesh.element(ei, ej), np.arange(mesh.n_elements))
    np.testing.assert_allclose(mesh.element_centroids(), np.stack([(ei + 0.5) * mesh.dx, -height / 2 + (ej + 0.5) * mesh.dy],
                                                                  1), rtol=0, atol=1e-14, err_msg="centroids")
    np.testing.assert_allclose(mesh.element_areas(), mesh.dx * mesh.dy, rtol=1e-12)
    a, b = fd.rod_joint_nodes(nx, ny)
    np.testing.assert_allclose(mesh.nodes[[a, b]], [[0.0, 0.0], [length, 0.0]], atol=1e-15, err_msg="joints A, B")
    plain = fd.QuadMesh(mesh.nodes, mesh.elements)
    assert plain == mesh and hash(plain) == hash(mesh), "a grid is the quad mesh of its content"


def test_rod_domain_orders_design_variables_as_the_reference_case():
    """The first and last element columns solid, the design row-major: `x.reshape(ny, nx - 2)[j, i - 1]`."""
    nx, ny = 6, 4
    domain = fd.rod_domain(nx, ny)
    assert domain.n_design == ny * (nx - 2)
    x = jnp.linspace(0.2, 0.9, domain.n_design)
    xe = np.asarray(domain.element_densities(x, 0.01))
    grid = np.asarray(x).reshape(ny, nx - 2)
    for j in range(ny):
        for i in range(nx):
            expected = 1.0 if i in (0, nx - 1) else grid[j, i - 1]
            assert xe[j * nx + i] == expected, f"element ({i}, {j})"
    np.testing.assert_array_equal(domain.design_grid(x), grid)
    centres = domain.mesh.element_centroids().reshape(ny, nx, 2)[:, 1:-1].reshape(-1, 2)
    np.testing.assert_allclose(domain.design_centroids(), centres, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="structured grid"):
        fd.DesignDomain(fd.QuadMesh(domain.mesh.nodes, domain.mesh.elements)).design_grid(np.zeros(nx * ny))


# --- meshio --------------------------------------------------------------------------------------


def test_meshio_round_trip_and_unused_nodes(tmp_path):
    import meshio

    mesh = fd.structured_grid(4, 2, 1.0, 0.2)
    path = tmp_path / "rod.vtu"
    fd.write_mesh(str(path), mesh, {"tag": np.arange(mesh.n_elements)})
    again = fd.read_mesh(str(path))
    assert again == mesh and hash(again) == hash(mesh), "a written and re-read mesh is the same mesh"
    # Lines, vertices and a node used only by them (as gmsh writes them) are dropped.
    points = np.vstack([mesh.nodes, [[5.0, 5.0]]])
    m = meshio.Mesh(points, [("vertex", np.array([[mesh.n_nodes]])), ("quad", mesh.elements),
                             ("line", np.array([[0, 1]]))], cell_data={"tag": [np.array([7]), np.arange(8), np.array([9])]})
    assert fd.from_meshio(m) == mesh
    np.testing.assert_array_equal(fd.quad_cell_data(m)["tag"], np.arange(8))
    with pytest.raises(ValueError, match="Unsupported cell types \\['triangle'\\]"):
        fd.from_meshio(meshio.Mesh(mesh.nodes, [("quad", mesh.elements), ("triangle", np.array([[0, 1, 5]]))]))
    with pytest.raises(ValueError, match="not planar"):
        fd.from_meshio(meshio.Mesh(np.c_[mesh.nodes, np.linspace(0, 1, mesh.n_nodes)], [("quad", mesh.elements)]))


# --- element checks --------------------------------------------------------------------------------


def test_clockwise_elements_are_reordered_or_refused():
    nodes, elements = _square_patch()
    flipped = elements.copy()
    flipped[[1, 2]] = flipped[[1, 2], ::-1]
    mesh = fd.QuadMesh(nodes, flipped)
    assert np.all(fd.QuadMesh(nodes, elements).element_areas() > 0)
    np.testing.assert_array_equal(np.sort(mesh.elements, axis=1), np.sort(elements, axis=1))
    assert np.all(mesh.element_areas() > 0), "reordered counter-clockwise"
    with pytest.raises(ValueError, match=r"Elements 1, 2 are numbered clockwise"):
        fd.QuadMesh(nodes, flipped, orientation="refuse")


@pytest.mark.parametrize("name, move, message", [
    ("bow-tie", lambda e: e[[0, 1, 3, 2]], "degenerate, non-convex or self-intersecting"),
    ("collapsed node", lambda e: e[[0, 1, 1, 3]], "repeat a node"),
])
def test_invalid_elements_are_refused(name, move, message):
    nodes, elements = _square_patch()
    elements = elements.copy()
    elements[2] = move(elements[2])
    with pytest.raises(ValueError, match=message):
        fd.QuadMesh(nodes, elements)


def test_non_convex_and_distorted_elements_are_refused():
    nodes, elements = _square_patch()
    dart = nodes.copy()
    dart[4] = [1.9, 1.9]  # centre node pushed past the diagonal of element 3: a re-entrant corner
    with pytest.raises(ValueError, match="Elements 3 are degenerate, non-convex"):
        fd.QuadMesh(dart, elements)
    skew = nodes.copy()
    skew[4] = [1.48, 1.48]  # still convex (x + y < 3), corner Jacobian ratio 0.04 in element 3
    assert fd.QuadMesh(skew, elements, min_jacobian_ratio=0.01).jacobian_ratios()[3] < 0.05
    with pytest.raises(ValueError, match="Elements 3 are badly distorted"):
        fd.QuadMesh(skew, elements)


def test_an_inverted_element_folded_over_its_neighbour_is_refused():
    """Element 1 is the mirror image of the unit square right of element 0, folded back over it (its
    nodes clockwise, so it is reordered, and then it runs along the shared edge 1-2 like element 0)."""
    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.3, 0.2], [0.3, 0.8]])
    elements = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    assert np.all(fd.QuadMesh(nodes[[0, 1, 2, 3]], elements[:1]).element_areas() > 0)
    with pytest.raises(ValueError, match=r"Elements 0, 1 overlap: .* nodes 1-2\), so an element is inverted"):
        fd.QuadMesh(nodes, elements)
    with pytest.raises(ValueError, match="Elements 1 are numbered clockwise"):
        fd.QuadMesh(nodes, elements, orientation="refuse")


def test_duplicate_elements_unused_and_duplicate_nodes_are_refused():
    nodes, elements = _square_patch()
    with pytest.raises(ValueError, match="Duplicate elements: 4 repeat"):
        fd.QuadMesh(nodes, np.vstack([elements, elements[1, [2, 3, 0, 1]]]))
    with pytest.raises(ValueError, match="Nodes 9 belong to no element"):
        fd.QuadMesh(np.vstack([nodes, [[3.0, 3.0]]]), elements)
    mesh, kept = fd.QuadMesh.without_unused_nodes(np.vstack([[[3.0, 3.0]], nodes]), elements + 1)
    assert mesh == fd.QuadMesh(nodes, elements) and np.array_equal(kept, np.arange(1, 10))
    # Node 9 duplicates node 4: elements 2 and 3 use the copy, the mesh is cut along x = 1.
    cut = elements.copy()
    cut[3, 0] = 9
    with pytest.raises(ValueError, match="Duplicate nodes: 1 pairs .* nodes 4 and 9"):
        fd.QuadMesh(np.vstack([nodes, nodes[4]]), cut)
    with pytest.raises(ValueError, match="outside \\[0, 9\\)"):
        fd.QuadMesh(nodes, elements + 1)
    with pytest.raises(ValueError, match="shape \\(n_elements, 4\\)"):
        fd.QuadMesh(nodes, elements[:, :3])


def test_identity_is_by_content():
    nodes, elements = _square_patch()
    a, b = fd.QuadMesh(nodes, elements), fd.QuadMesh(nodes.copy(), elements.copy())
    assert a == b and hash(a) == hash(b) and a is not b
    moved = nodes.copy()
    moved[4] += 1e-3
    assert fd.QuadMesh(moved, elements) != a
    assert fd.QuadMesh(nodes, elements[::-1]) != a, "element order is part of the mesh"
    with pytest.raises(ValueError, match="read-only"):
        a.nodes[0, 0] = 1.0
    with pytest.raises(AttributeError, match="immutable"):
        a.nodes = moved


def test_jit_caches_one_program_per_mesh_content():
    traces = []

    def area(model, v):
        traces.append(1)
        return jnp.sum(model.unit_mass[:, 0, 0] * v)

    f = jax.jit(area)
    nodes, elements = _square_patch()
    for _ in range(2):  # a new but equal mesh and model each time: no new trace
        model = fd.FEModel(fd.QuadMesh(nodes.copy(), elements.copy()), fd.Q4(), 1.0)
        f(model, jnp.ones(4))
    assert len(traces) == 1, "equal meshes reuse the compiled program"


# --- roles -----------------------------------------------------------------------------------------


def test_roles_from_masks_and_bad_designs():
    mesh = fd.structured_grid(4, 2, 1.0, 0.5)
    solid = np.zeros(8, bool)
    solid[[0, 4]] = True
    void = np.zeros(8, bool)
    void[[3]] = True
    domain = fd.DesignDomain.from_masks(mesh, solid=solid, void=void)
    assert domain.n_design == 5
    np.testing.assert_array_equal(np.asarray(domain.design_elements), [1, 2, 5, 6, 7])
    xe = domain.element_densities(jnp.full(5, 0.5), 0.01)
    np.testing.assert_array_equal(xe, [1.0, 0.5, 0.5, 0.01, 1.0, 0.5, 0.5, 0.5])
    jac = jax.jacobian(lambda x: domain.element_densities(x, 0.01))(jnp.full(5, 0.5))
    assert np.all(np.asarray(jac)[[0, 3, 4]] == 0.0), "passive elements do not depend on the design"
    with pytest.raises(ValueError, match="shape \\(4,\\), expected \\(5,\\)"):
        domain.check(jnp.ones(4), 0.01)
    with pytest.raises(ValueError, match="both solid and void"):
        fd.DesignDomain.from_masks(mesh, solid=solid, void=solid)
    with pytest.raises(ValueError, match="no design element"):
        fd.DesignDomain.from_masks(mesh, solid=np.ones(8, bool))


# --- a large mesh is configuration, its arrays are program inputs -----------------------------------


def _lowered_size(nx, ny):
    """Characters of the HLO text of the FE stage (body data and its gradient) on an nx x ny mesh."""
    import equinox as eqx

    domain = fd.rod_domain(nx, ny)
    a, b = fd.rod_joint_nodes(nx, ny)
    model = fd.FEModel(domain.mesh, fd.Q4(), 0.01)
    body = fd.DesignedBody(model, domain, fd.SIMP(), fd.ModalReduction(6, fd.HingedHinged(a, b), solver=fd.LanczosModes()),
                           (a, b))

    def stage(body, x):
        return jax.grad(lambda x: jnp.trace(body.body_data(x).modal_stiffness))(x)

    return len(eqx.filter_jit(stage).lower(body, body.initial_design(0.5)).as_text())


def test_large_mesh_arrays_are_program_inputs_not_constants():
    """On 10^5 elements the compiled FE stage is as small as on 10^3: no mesh-sized constant.

    A single embedded index array of the large mesh ((10^5, 8) element dofs) would add about
    10^7 characters of HLO text; the program text must not grow with the mesh.
    """
    small, large = _lowered_size(50, 20), _lowered_size(1000, 100)
    assert large < 1.2 * small, f"HLO text grows with the mesh: {small} -> {large} characters"


def test_largest_rod_layout_and_matrix_free_mass():
    """1000 x 100 elements (99,800 design variables, 202,202 dofs): layout and a matrix-free product.

    The total mass `e_x^T M e_x` equals `sum_e rho_e dx dy t` (the consistent mass integrates a
    constant exactly); the two sums over 10^5 terms differ by round-off, 1e-12 relative.
    """
    import ffr_jax as fj

    body = fj.cases.rod_body(1000, 100, 6)
    assert body.n_design == 99_800 and body.mesh.n_dof == 202_202
    _, rho = body.element_values(body.initial_design(0.5))
    e_x = jnp.zeros(body.mesh.n_dof).at[0::2].set(1.0)
    mass = e_x @ (body.model.mass(rho) @ e_x)
    expected = float(jnp.sum(rho)) * body.mesh.dx * body.mesh.dy * body.model.thickness
    np.testing.assert_allclose(mass, expected, rtol=1e-12, err_msg="total mass of the 1000 x 100 rod")
    np.testing.assert_allclose(body.mesh.nodes[list(body.markers)], [[0.0, 0.0], [1.0, 0.0]], atol=1e-12)
