"""Solid meshes and their assembly (issue 27): box grids with masks, meshio files, K(x) and M(x) in 3D.

Checks: the grid's layout and its mask; hex_to_tet10; a meshio round trip of hexahedra and
tetra10; SIMP-scaled K and M agree between the matrix-free operator, JAX BCOO, dense assembly and
SciPy CSC, with the six rigid motions as the null space of K and the mass and first moments in M;
**exactness against the planar model**: the reference rod meshed with one layer of H8 through its
thickness, nu = 0, has the in-plane free-free frequencies of the Q4 plane-stress rod to 1e-10;
bad meshes refused with clear errors.
"""

import jax
import jax.numpy as jnp
import meshio
import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg as spla

import ffr_jax._design as fd
from ffr_jax._design.element import H8, H11, Tet10
from ffr_jax._design.solid_assembly import (SolidFEModel, solid_bcoo, solid_csc_matrices, solid_dense_matrix)
from ffr_jax._design.solid_mesh import (SolidMesh, box_grid, hex_to_tet10, read_solid_mesh, solid_cell_data,
                                       solid_from_meshio)

EPS = np.finfo(float).eps
ROUNDOFF = 1e-12  # vanishing quantities relative to their scale: a few hundred eps (sums of element products)


def test_box_grid_layout_and_mask():
    """Node and cell numbering of the grid; the mask drops cells and the nodes only they used."""
    grid = box_grid(3, 2, 2, 0.3, 0.2, 0.1)
    assert (grid.n_nodes, grid.n_elements, grid.n_dof) == (4 * 3 * 3, 12, 108)
    np.testing.assert_allclose(grid.nodes.min(axis=0), [0.0, -0.1, -0.05], rtol=0, atol=ROUNDOFF)
    np.testing.assert_allclose(grid.nodes.max(axis=0), [0.3, 0.1, 0.05], rtol=0, atol=ROUNDOFF)
    np.testing.assert_allclose(grid.element_volumes(), 0.1 * 0.1 * 0.05, rtol=ROUNDOFF)
    # cell (i, j, k) = (2, 1, 1) is element (k ny + j) nx + i = 11, its first node the grid node (2, 1, 1)
    assert grid.cells[11] == 11
    np.testing.assert_allclose(grid.nodes[grid.elements[11, 0]], [0.2, 0.0, 0.0], atol=ROUNDOFF)
    mask = np.ones((3, 2, 2), dtype=bool)
    mask[2, :, :] = False  # the last column of cells: its far face of 9 nodes goes
    cut = box_grid(3, 2, 2, 0.3, 0.2, 0.1, mask)
    assert (cut.n_elements, cut.n_nodes) == (8, 27)
    np.testing.assert_array_equal(cut.cells, np.flatnonzero(mask.transpose(2, 1, 0).ravel()))
    assert cut.nodes[:, 0].max() == pytest.approx(0.2)
    assert cut != grid and hash(cut) != hash(grid) and box_grid(3, 2, 2, 0.3, 0.2, 0.1) == grid


def test_hex_to_tet10_is_conforming_and_keeps_volume():
    grid = box_grid(2, 2, 1, 1.0, 1.0, 0.5)
    tets = hex_to_tet10(grid)
    assert tets.cell_type == "tetra10" and tets.n_elements == 6 * grid.n_elements
    np.testing.assert_allclose(tets.element_volumes().sum(), 0.5, rtol=ROUNDOFF)
    # conforming: every interior face (three vertices) is shared by exactly two tetrahedra
    faces = np.sort(np.concatenate([tets.elements[:, f] for f in ([0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3])]), 1)
    _, counts = np.unique(faces, axis=0, return_counts=True)
    assert set(counts) == {1, 2}


@pytest.mark.parametrize("cells", ["hexahedron", "tetra10"])
def test_meshio_round_trip(tmp_path, cells):
    """A mesh written by meshio (with boundary quads and an unused point) reads back as the same mesh."""
    grid = box_grid(2, 1, 1, 1.0, 0.5, 0.5)
    mesh = grid if cells == "hexahedron" else hex_to_tet10(grid)
    points = np.concatenate([mesh.nodes, [[9.0, 9.0, 9.0]]])
    boundary = ("quad", grid.elements[:, :4]) if cells == "hexahedron" else ("triangle", mesh.elements[:1, :3])
    path = tmp_path / "part.vtu"
    tags = np.arange(mesh.n_elements) % 3
    meshio.write(path, meshio.Mesh(points, [(cells, mesh.elements), boundary],
                                   cell_data={"region": [tags, np.zeros(len(boundary[1]), dtype=int)]}))
    back = read_solid_mesh(path)
    assert back == mesh and back.cell_type == cells
    np.testing.assert_array_equal(solid_cell_data(meshio.read(path))["region"], tags)


def test_meshio_bad_files_and_cells(tmp_path):
    with pytest.raises(FileNotFoundError, match="no mesh file"):
        read_solid_mesh(tmp_path / "missing.msh")
    garbage = tmp_path / "garbage.vtu"
    garbage.write_text("not a mesh")
    with pytest.raises(ValueError, match="meshio could not read"):
        read_solid_mesh(garbage)
    nodes = box_grid(1, 1, 1, 1.0, 1.0, 1.0).nodes
    with pytest.raises(ValueError, match="Linear tetrahedra lock"):
        solid_from_meshio(meshio.Mesh(nodes, [("tetra", np.array([[0, 2, 4, 1]]))]))
    with pytest.raises(ValueError, match="exactly one of the cell types"):
        solid_from_meshio(meshio.Mesh(nodes, [("quad", np.array([[0, 2, 6, 4]]))]))


def test_bad_meshes_are_refused_with_the_element_named():
    grid = box_grid(2, 1, 1, 2.0, 1.0, 1.0)
    nodes, elements = np.array(grid.nodes), np.array(grid.elements)
    inverted = elements.copy()
    inverted[1] = inverted[1][[4, 5, 6, 7, 0, 1, 2, 3]]
    with pytest.raises(ValueError, match=r"H8 elements 1 are inverted .*orientation='reorder'"):
        SolidMesh(nodes, inverted)
    assert SolidMesh(nodes, inverted, orientation="reorder") == grid
    flat = nodes.copy()
    flat[elements[1, 4:], 2] = flat[elements[1, :4], 2]  # element 1's top face moved onto its bottom
    with pytest.raises(ValueError, match="H8 elements 1 are degenerate"):
        SolidMesh(flat, elements)
    repeated = elements.copy()
    repeated[0, 1] = repeated[0, 0]
    with pytest.raises(ValueError, match="H8 elements 0 repeat a node"):
        SolidMesh(nodes, repeated)
    with pytest.raises(ValueError, match="belong to no element"):
        SolidMesh(np.concatenate([nodes, [[5.0, 5.0, 5.0]]]), elements)
    with pytest.raises(ValueError, match="Duplicate H8 elements: 1"):
        SolidMesh(nodes, elements[[0, 0]])
    with pytest.raises(ValueError, match="outside"):
        SolidMesh(nodes, elements + 100)
    with pytest.raises(ValueError, match=r"\(n_elements, 8\)"):
        SolidMesh(nodes, elements[:, :6])
    tets = hex_to_tet10(grid)
    inverted = np.array(tets.elements)
    inverted[3] = inverted[3][Tet10().reordered()]
    with pytest.raises(ValueError, match="Tet10 elements 3 are inverted"):
        SolidMesh(tets.nodes, inverted)
    with pytest.raises(ValueError, match="Tet10 elements need a mesh of tetra10 cells"):
        SolidFEModel(grid, Tet10())
    with pytest.raises(ValueError, match="mask must be a boolean array"):
        box_grid(2, 1, 1, 2.0, 1.0, 1.0, np.ones((1, 1, 1), dtype=bool))


# --- assembly --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def masked_model():  # NumPy only: the element matrices are computed on the host
    mask = np.ones((3, 2, 2), dtype=bool)
    mask[1, 1, :] = False  # a notch
    return SolidFEModel(box_grid(3, 2, 2, 0.3, 0.2, 0.1, mask), H11(), 0.3)


def _numpy_dense(model, values, kind):
    """Reference assembly, one element at a time."""
    out = np.zeros((model.n_dof, model.n_dof))
    unit = np.asarray(model.unit_stiffness if kind == "stiffness" else model.unit_mass)
    for e, dofs in enumerate(np.asarray(model.element_dofs)):
        out[np.ix_(dofs, dofs)] += float(values[e]) * unit[e]
    return out


def test_csc_assembly_rigid_null_space_mass_and_moments(masked_model):
    """K(x), M(x) with SIMP on the host (CSC) = element-by-element assembly (round-off of sums of <= 8
    element entries); K annihilates the rigid motions; M gives the mass and the first moment of the
    element densities (the centroid of a box is its vertex mean)."""
    model = masked_model
    simp = fd.SIMP()
    x = jnp.linspace(0.2, 1.0, model.n_elements)
    youngs, densities = np.asarray(simp.youngs(x)), np.asarray(simp.densities(x))
    csc_k, csc_m = solid_csc_matrices(model, youngs, densities)
    for csc, values, kind in ((csc_k, youngs, "stiffness"), (csc_m, densities, "mass")):
        dense = _numpy_dense(model, values, kind)
        np.testing.assert_allclose(csc.toarray(), dense, rtol=0, atol=ROUNDOFF * np.abs(dense).max(), err_msg=kind)
    xyz = np.asarray(model.coordinates)
    zero = 0 * xyz[:, 0]
    scale = abs(csc_k).max()
    for u in (np.tile([1.0, 0, 0], model.mesh.n_nodes), np.stack([-xyz[:, 1], xyz[:, 0], zero], 1).ravel(),
              np.stack([zero, -xyz[:, 2], xyz[:, 1]], 1).ravel(), np.stack([xyz[:, 2], zero, -xyz[:, 0]], 1).ravel()):
        assert np.linalg.norm(csc_k @ u) <= ROUNDOFF * scale * np.linalg.norm(u), "force of a rigid motion"
    volumes = model.mesh.element_volumes()
    ex = np.tile([1.0, 0.0, 0.0], model.mesh.n_nodes)
    mass = np.sum(densities * volumes)
    np.testing.assert_allclose(ex @ csc_m @ ex, mass, rtol=ROUNDOFF, err_msg="total mass")
    centroids = np.stack([model.mesh.nodes[e].mean(axis=0) for e in model.mesh.elements])
    np.testing.assert_allclose(ex @ csc_m @ np.stack([xyz[:, 1], zero, zero], 1).ravel(),
                               np.sum(densities * volumes * centroids[:, 1]), rtol=0, atol=ROUNDOFF * mass * 0.2,
                               err_msg="first moment along y (the notch makes it nonzero)")


@pytest.mark.slow
def test_jax_assemblies_agree_and_are_differentiable(masked_model):
    """Matrix-free = BCOO = dense (JAX) = CSC, and `d/dx (v^T K(x) v) = p x^(p-1) E0 v_e^T K_e v_e` per
    element (the SIMP derivative) through BCOO. (Slow: compiles a few small programs, ~4 s.)"""
    model = masked_model
    simp = fd.SIMP()
    x = jnp.linspace(0.2, 1.0, model.n_elements)
    youngs, densities = simp.youngs(x), simp.densities(x)
    v = jax.random.normal(jax.random.PRNGKey(0), (model.n_dof, 2), dtype=jnp.float64)
    csc_k, csc_m = solid_csc_matrices(model, np.asarray(youngs), np.asarray(densities))
    for csc, values, kind in ((csc_k, youngs, "stiffness"), (csc_m, densities, "mass")):
        reference = csc @ np.asarray(v)
        atol = ROUNDOFF * abs(csc).max() * float(jnp.abs(v).max())
        op = model.stiffness(values) if kind == "stiffness" else model.mass(values)
        np.testing.assert_allclose(op @ v, reference, rtol=0, atol=atol, err_msg=f"matrix-free {kind}")
        np.testing.assert_allclose(solid_bcoo(model, values, kind) @ v, reference, rtol=0, atol=atol,
                                   err_msg=f"BCOO {kind}")
        np.testing.assert_allclose(solid_dense_matrix(model, values, kind), csc.toarray(), rtol=0,
                                   atol=ROUNDOFF * abs(csc).max(), err_msg=f"dense {kind}")
    w = v[:, 0]
    x = jnp.full(model.n_elements, 0.5)
    grad = jax.grad(lambda x: w @ (solid_bcoo(model, simp.youngs(x), "stiffness") @ w))(x)
    local = w[model.element_dofs]
    expected = 3 * 0.5**2 * simp.youngs_modulus * jnp.einsum("ea,eab,eb->e", local, model.unit_stiffness, local)
    np.testing.assert_allclose(grad, expected, rtol=ROUNDOFF)


# --- exactness against the planar model -----------------------------------------------------------

# The reference rod (REFERENCE_CASE §1): L = 1, h = 0.06, thickness b = 0.01, 100 x 6 elements, solid.
ROD_L, ROD_H, ROD_B, ROD_NX, ROD_NY = 1.0, 0.06, 0.01, 100, 6
E0, RHO0 = 0.5e11, 8750.0
N_PLANAR = 8  # elastic in-plane free-free modes compared (up to 1.75 kHz)


def _lowest_modes(k, m, n):
    """`n` lowest eigenpairs of the free-free pencil (shift-invert below zero: K - sigma M is definite),
    eigenvalues as Rayleigh quotients, and each quotient's round-off scale
    `(|phi|^T |K| |phi|) / (phi^T K phi) + (|phi|^T |M| |phi|) / (phi^T M phi)` (the cancellation factor)."""
    _, v = spla.eigsh(k, n, m, sigma=-1e2, which="LM", tol=0)
    kv, mv = k @ v, m @ v
    num, den = np.einsum("ni,ni->i", v, kv), np.einsum("ni,ni->i", v, mv)
    a = np.abs(v)
    cancel = np.einsum("ni,ni->i", a, abs(k) @ a) / np.abs(num) + np.einsum("ni,ni->i", a, abs(m) @ a) / den
    order = np.argsort(num / den)
    return (num / den)[order], v[:, order], cancel[order]


@pytest.fixture(scope="module")
def rod_models():
    n = ROD_NX * ROD_NY
    planar = fd.FEModel(fd.structured_grid(ROD_NX, ROD_NY, ROD_L, ROD_H), fd.Q4(), ROD_B, 0.0)
    kq, mq = fd.csc_matrices(planar.mesh, np.full(n, E0), np.full(n, RHO0), np.asarray(planar.unit_stiffness),
                             np.asarray(planar.unit_mass))
    solid = SolidFEModel(box_grid(ROD_NX, ROD_NY, 1, ROD_L, ROD_H, ROD_B), H8(), 0.0)
    ks, ms = solid_csc_matrices(solid, np.full(n, E0), np.full(n, RHO0))
    # Q4 node q = i (ny + 1) + j lies under the H8 nodes 2 q (bottom) and 2 q + 1 (top) (grid index
    # (i (ny + 1) + j)(nz + 1) + k, all nodes kept): the lift copies (u_x, u_y) to both, u_z = 0.
    q = np.arange(planar.mesh.n_nodes)
    rows = np.concatenate([3 * (2 * q + layer) + c for layer in (0, 1) for c in (0, 1)])
    cols = np.concatenate([2 * q + c for layer in (0, 1) for c in (0, 1)])
    lift = scipy.sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(solid.n_dof, planar.n_dof))
    return kq, mq, ks, ms, lift


def test_one_layer_of_h8_is_the_q4_rod_at_the_matrix_level(rod_models):
    """Why the frequencies agree exactly: with one layer and nu = 0, the lifted in-plane fields span an
    invariant subspace of the H8 pencil on which it *is* the Q4 pencil.

    In an extruded H8 with top and bottom nodes moving alike and `u_z = 0`, the field is the Q4 field
    (the two layers' trilinear functions sum to the bilinear one), `eps_zz = gamma_xz = gamma_yz = 0`,
    and `det J = det J_Q4 b / 2` at each of the two Gauss points through the thickness: the energy and
    kinetic energy are `b` times the Q4 integrands, the 3D `D` with nu = 0 being the plane-stress `D`
    on the in-plane strains. So `L^T K_H8 L = K_Q4` and `L^T M_H8 L = M_Q4`. The subspace is invariant
    (`K_H8 L`, `M_H8 L` have no `u_z` part and equal top and bottom parts), because with nu = 0 the
    in-plane strains do not couple to `eps_zz` (D diagonal) and the mid-plane symmetry `z -> -z`
    separates the even in-plane fields from the odd ones. Tolerance: sums of a few dozen products per
    entry (ROUNDOFF of the largest entry).
    """
    kq, mq, ks, ms, lift = rod_models
    for planar, solid, name in ((kq, ks, "K"), (mq, ms, "M")):
        scale = np.abs(planar).max()
        assert abs(lift.T @ solid @ lift - planar).max() <= ROUNDOFF * scale, f"L^T {name}_H8 L = {name}_Q4"
        image = solid @ lift
        back = lift @ (lift.T @ image) / 2  # the part of the image in the lifted subspace (L^T L = 2 I)
        assert abs(image - back).max() <= ROUNDOFF * scale, f"{name}_H8 maps the in-plane subspace into itself"


def test_one_layer_of_h8_has_the_free_free_frequencies_of_the_q4_rod(rod_models):
    """**Exactness against the planar model** (issue 27): the reference rod meshed with one layer of H8
    through its thickness, nu = 0, has the in-plane free-free frequencies of the Q4 plane-stress rod
    (nu = 0) to 1e-10 (relative), each found in the H8 spectrum among its out-of-plane modes.

    Why exact: see the matrix-level test above (the Q4 pencil is the H8 pencil on an invariant
    subspace). Tolerance: each eigenvalue is a Rayleigh quotient of a computed eigenvector, whose
    eigenvector error enters squared (negligible) and whose round-off is at most
    `eps x` the cancellation factor of [`_lowest_modes`][] (up to 3e5 for the lowest mode, where
    elements move nearly rigidly): 7e-11 on `lambda` per side, so `|df / f| = |dlam / lam| / 2 <= eps
    (c_Q4 + c_H8) / 2`, asserted below 1e-10 (measured 100x below the bound).
    """
    kq, mq, ks, ms, _ = rod_models
    lam_q, _, cancel_q = _lowest_modes(kq, mq, 3 + N_PLANAR)
    lam_s, _, cancel_s = _lowest_modes(ks, ms, 36)
    scale_q = lam_q[-1]
    assert np.all(np.abs(lam_q[:3]) < 1e-6 * scale_q), "Q4: three rigid-body modes"
    assert np.all(np.abs(lam_s[:6]) < 1e-6 * scale_q), "H8: six rigid-body modes"
    for i in range(3, 3 + N_PLANAR):
        j = np.argmin(np.abs(lam_s - lam_q[i]))
        difference = abs(np.sqrt(lam_s[j] / lam_q[i]) - 1.0)
        bound = EPS * (cancel_q[i] + cancel_s[j]) / 2
        assert bound < 1e-10, f"mode {i}: the check cannot show 1e-10 (round-off bound {bound:.1e})"
        assert difference <= bound, (f"in-plane mode {i - 2}: f_H8 / f_Q4 - 1 = {difference:.1e} "
                                     f"(bound {bound:.1e}, f = {np.sqrt(lam_q[i]) / (2 * np.pi):.2f} Hz)")


# --- modal analysis of a free solid part ------------------------------------------------------------


FREE_L, FREE_H = 1.0, 0.02  # L / h = 50, square section, E = 2e11, rho = 7800, nu = 0


def _free_beam(nx):
    from ffr_jax._design.solid_modes import free_modes_sparse

    model = SolidFEModel(box_grid(nx, 1, 1, FREE_L, FREE_H, FREE_H), H11(), 0.0)
    lam, phi = free_modes_sparse(model, np.full(model.n_elements, 2e11), np.full(model.n_elements, 7800.0), 4)
    return model, lam, phi


def test_free_free_solid_beam_frequencies_against_beam_theory():
    """The four lowest elastic modes of a free H11 beam (100 x 1 x 1 cells) are its first two bending
    pairs (y and z, square section), at the Euler–Bernoulli free-free frequencies
    `f_n = (beta_n L)^2 sqrt(E I / (rho A)) / (2 pi L^2)`, `beta_n L = 4.7300, 7.8532`, lowered by
    shear and rotary inertia by about `c_n = 1/2 (beta_n r)^2 (1 + E / (kappa G))` (Timoshenko,
    `r^2 = I / A`; 1.3e-3 and 3.5e-3 here): each frequency must lie below Euler–Bernoulli by no more
    than `2 c_n` (the first-order estimate is within a factor two of the exact shift; the
    discretisation error of H11 is 1e-4 and below, see the cantilever test). The modes carry no
    rigid-body part (`R^T M Phi = 0`, to the solver's accuracy `n eps cond`, here 1e-9 of `|R| |M Phi|`).
    """
    from ffr_jax._design.solid_modes import rigid_motions

    model, lam, phi = _free_beam(100)
    beta = np.array([4.730040744862704, 7.853204624095838])
    euler_bernoulli = beta**2 * np.sqrt(2e11 * FREE_H**2 / 12 / 7800.0) / (2 * np.pi * FREE_L**2)
    shift = 0.5 * (beta * FREE_H / np.sqrt(12) / FREE_L) ** 2 * (1 + 2 / (5 / 6))
    error = np.sqrt(lam) / (2 * np.pi) / np.repeat(euler_bernoulli, 2) - 1
    assert np.all(error < 0) and np.all(error > -2 * np.repeat(shift, 2)), f"free-free frequency errors {error}"
    _, m = solid_csc_matrices(model, np.full(model.n_elements, 2e11), np.full(model.n_elements, 7800.0))
    r = rigid_motions(model.mesh.nodes)
    m_phi = m @ phi
    np.testing.assert_allclose(phi.T @ m_phi, np.eye(4), rtol=0, atol=1e-9, err_msg="Phi^T M Phi = I")
    rigid_part = np.abs(r.T @ m_phi).max() / (np.abs(r).sum(axis=0).max() * np.abs(m_phi).max())
    assert rigid_part < 1e-9, f"rigid-body part of the elastic modes {rigid_part:.1e}"


@pytest.mark.slow
def test_free_modes_dense_equals_sparse_and_has_a_derivative():
    """The dense (JAX, deflated) and sparse (host) free-free solvers agree on a small beam of rectangular
    section (simple eigenvalues): eigenvalues to `n eps lam_max` each (the dense solver's absolute accuracy),
    the span of the four modes through its projector to the Davis–Kahan bound `n eps lam_max / gap`
    (gap to the fifth eigenvalue; x10 for the product of the two solvers' errors and the projector's
    round-off); the dense eigenvalue's design derivative is the classic `dlam_1/dE_e = phi_1^T K_e phi_1`
    (unit `K_e`), to the round-off of the element sums (1e-8 relative is 1e5 eps, far above it and far below
    a wrong term, which would be O(1))."""
    from ffr_jax._design.solid_modes import free_modes_dense, free_modes_sparse

    model = SolidFEModel(box_grid(20, 1, 1, FREE_L, 0.1, 0.05), H11(), 0.0)
    n = model.n_elements
    e, rho = jnp.full(n, 2e11), jnp.full(n, 7800.0)
    lam_d, phi_d = free_modes_dense(model, e, rho, 4)
    lam_s, phi_s = free_modes_sparse(model, e, rho, 5)
    k, m = solid_csc_matrices(model, np.asarray(e), np.asarray(rho))
    lam_max = scipy.linalg.eigh(k.toarray(), m.toarray(), eigvals_only=True)[-1]
    bound = model.n_dof * EPS * lam_max
    np.testing.assert_allclose(lam_d, lam_s[:4], rtol=0, atol=2 * bound, err_msg="eigenvalues")
    proj_d, proj_s = phi_d @ phi_d.T, phi_s[:, :4] @ phi_s[:, :4].T
    np.testing.assert_allclose(proj_d, proj_s, rtol=0, atol=10 * bound / (lam_s[4] - lam_s[3]) * np.abs(proj_s).max(),
                               err_msg="projector onto the span of the four modes")
    grad = jax.grad(lambda e: free_modes_dense(model, e, rho, 4)[0][0])(e)
    local = phi_d[model.element_dofs, 0]
    np.testing.assert_allclose(grad, jnp.einsum("ea,eab,eb->e", local, model.unit_stiffness, local), rtol=1e-8)


@pytest.mark.slow
def test_gmsh_tetra10_part_free_free_frequencies(tmp_path):
    """A CAD part through gmsh (OpenCASCADE box, second-order tetrahedra, one physical volume) written as
    .msh and read by `read_solid_mesh`: Tet10 on this unstructured mesh gives the free-free bending
    frequencies of the slender box (L / h = 20, square section, nu = 0) below Euler–Bernoulli by no more
    than `2 c_n` (Timoshenko's first-order shift, 7.9e-3 and 2.2e-2 here, as in the test above; the
    discretisation error with two quadratic tetrahedra across is a few 1e-4, see the cantilever tests),
    and the physical tag of every element through `solid_cell_data`. (Slow: meshing and 5,661 dofs, ~2 s;
    measured -0.80 % / -0.80 % and -2.1 % / -2.1 %, against shifts of 0.79 % and 2.2 %.)"""
    gmsh = pytest.importorskip("gmsh")
    length, h = 1.0, 0.05
    path = tmp_path / "beam.msh"
    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("ffr_jax_solid_beam")
        box = gmsh.model.occ.addBox(0.0, -h / 2, -h / 2, length, h, h)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(3, [box], 7, name="beam")
        gmsh.option.setNumber("Mesh.MeshSizeMax", h / 2)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
        gmsh.model.remove()
    finally:
        if not initialised:
            gmsh.finalize()
    mesh = read_solid_mesh(path)
    assert mesh.cell_type == "tetra10"
    np.testing.assert_array_equal(solid_cell_data(meshio.read(path))["gmsh:physical"], 7)
    np.testing.assert_allclose(mesh.element_volumes().sum(), length * h * h, rtol=ROUNDOFF)
    from ffr_jax._design.solid_modes import free_modes_sparse

    model = SolidFEModel(mesh, Tet10(), 0.0)
    lam, _ = free_modes_sparse(model, np.full(mesh.n_elements, 2e11), np.full(mesh.n_elements, 7800.0), 4)
    beta = np.array([4.730040744862704, 7.853204624095838])
    euler_bernoulli = beta**2 * np.sqrt(2e11 * h**2 / 12 / 7800.0) / (2 * np.pi * length**2)
    shift = 0.5 * (beta * h / np.sqrt(12) / length) ** 2 * (1 + 2 / (5 / 6))
    error = np.sqrt(lam) / (2 * np.pi) / np.repeat(euler_bernoulli, 2) - 1
    assert np.all(error < 0) and np.all(error > -2 * np.repeat(shift, 2)), f"free-free frequency errors {error}"
