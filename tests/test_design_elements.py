"""Elements, material and assembly: Q4 and QM6 (no bending locking), SIMP, global K and M.

Checks: the closed-form consistent mass and constant-strain energy of a rectangle, rigid-body null
space, the patch test on the distorted MacNeal–Harder patch, exact pure bending of QM6, the first
frequency of a slender 10 m cantilever against Euler–Bernoulli; the SIMP law; assembled K (null
space = rigid motions), M (mass, first moment), dense = matrix-free = SciPy CSC; a beam's static
deflection and hinged–hinged frequencies against beam theory.
"""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse.linalg

import ffr_jax._design as fd

ELEMENTS = [fd.Q4(), fd.QM6()]
IDS = ["Q4", "QM6"]
# Quantities that vanish in exact arithmetic, relative to their scale (double precision with
# a few dozen operations per entry; the condensation of QM6 solves a 4 x 4 system).
ROUNDOFF = 1e-12

# A rectangle, a parallelogram and a general convex quadrilateral (counter-clockwise).
SHAPES = {
    "rectangle": np.array([[0.0, 0.0], [0.02, 0.0], [0.02, 0.005], [0.0, 0.005]]),
    "parallelogram": np.array([[0.0, 0.0], [1.0, 0.0], [1.5, 0.7], [0.5, 0.7]]),
    "general": np.array([[0.0, 0.0], [1.0, 0.1], [1.3, 0.9], [-0.2, 0.6]]),
}


def _nodal(field, xy):
    return np.stack([np.asarray(field(x, y), dtype=float) for x, y in xy]).ravel()


def _plane_stress(nu):
    return np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)


@pytest.mark.parametrize("dx, dy, nu, t", [(0.01, 0.01, 0.3, 0.01), (0.02, 0.005, 0.3, 0.01), (1.0, 2.0, 0.45, 1.0)])
def test_q4_rectangle_mass_and_constant_strain_energy(dx, dy, nu, t):
    """The exact consistent mass of a bilinear rectangle, `t dx dy / 36 [4 2 1 2; ...]` per component
    (2x2 Gauss integrates `N^T N` exactly there), and the continuum energy `1/2 eps^T D eps V` of a
    linear field (`E = 1`), both elements."""
    xy = np.array([[0.0, 0.0], [dx, 0.0], [dx, dy], [0.0, dy]]) + 0.37  # position does not matter
    scalar = dx * dy * t / 36.0 * np.array([[4.0, 2.0, 1.0, 2.0], [2.0, 4.0, 2.0, 1.0], [1.0, 2.0, 4.0, 2.0],
                                           [2.0, 1.0, 2.0, 4.0]])
    rng = np.random.default_rng(0)
    a, b, c, d = rng.normal(size=4)
    # Measured from the first corner: the translation a linear field adds elsewhere stores no energy,
    # but its cancellation in u^T K u would cost digits (offset / element size squared).
    u = _nodal(lambda x, y: (a * (x - 0.37) + b * (y - 0.37), c * (x - 0.37) + d * (y - 0.37)), xy)
    eps = np.array([a, d, b + c])
    energy = 0.5 * eps @ _plane_stress(nu) @ eps * dx * dy * t
    for element in ELEMENTS:
        k, m = (arr[0] for arr in element.matrices(xy[None], nu, t))
        np.testing.assert_allclose(m[0::2, 0::2], scalar, rtol=ROUNDOFF, err_msg="x-x block of the element mass")
        np.testing.assert_allclose(m[1::2, 1::2], scalar, rtol=ROUNDOFF, err_msg="y-y block of the element mass")
        assert np.all(m[0::2, 1::2] == 0.0), "x-y coupling of the element mass"
        np.testing.assert_allclose(0.5 * u @ k @ u, energy, rtol=ROUNDOFF, err_msg="energy of a constant strain")


def test_simp_law():
    """Paper eq. 47 with the REFERENCE_CASE constants; the density is continuous at the switch x = 0.1."""
    simp = fd.SIMP()
    x = jnp.array([0.01, 0.05, 0.0999, 0.1, 0.3, 1.0])
    low = 1e5 * x**6 * 8750.0
    np.testing.assert_allclose(simp.densities(x), jnp.where(x < 0.1, low, x * 8750.0), rtol=ROUNDOFF)
    np.testing.assert_allclose(simp.youngs(x), x**3 * 0.5e11, rtol=ROUNDOFF)
    below, above = simp.densities(jnp.array([0.1 - 1e-9, 0.1]))
    np.testing.assert_allclose(below, above, rtol=1e-7, err_msg="density continuity at x = 0.1")


@pytest.mark.parametrize("element", ELEMENTS, ids=IDS)
@pytest.mark.parametrize("shape", list(SHAPES))
def test_element_null_space_is_the_rigid_motions(element, shape):
    xy = SHAPES[shape]
    k, m = (a[0] for a in element.matrices(xy[None], 0.3, 0.1))
    scale = np.abs(k).max()
    assert np.allclose(k, k.T, rtol=0, atol=ROUNDOFF * scale), "symmetry"
    for u in (_nodal(lambda x, y: (1.0, 0.0), xy), _nodal(lambda x, y: (0.0, 1.0), xy), _nodal(lambda x, y: (-y, x), xy)):
        assert np.linalg.norm(k @ u) <= ROUNDOFF * scale * np.linalg.norm(u), "force of a rigid motion"
    lam = np.linalg.eigvalsh(k)
    assert np.sum(np.abs(lam) <= 1e-10 * lam[-1]) == 3 and lam[3] > 1e-4 * lam[-1], f"three zero eigenvalues: {lam}"
    area = fd.QuadMesh(xy, [[0, 1, 2, 3]]).element_areas()[0]
    ex = np.tile([1.0, 0.0], 4)
    np.testing.assert_allclose(ex @ m @ ex, area * 0.1, rtol=ROUNDOFF, err_msg="element mass")


# The MacNeal–Harder patch: a 0.24 x 0.12 rectangle of five distorted quadrilaterals.
PATCH_NODES = np.array([[0.0, 0.0], [0.24, 0.0], [0.24, 0.12], [0.0, 0.12],
                        [0.04, 0.02], [0.18, 0.03], [0.16, 0.08], [0.08, 0.08]])
PATCH_ELEMENTS = np.array([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7], [4, 5, 6, 7]])


@pytest.mark.parametrize("element", ELEMENTS, ids=IDS)
def test_patch_test_on_a_distorted_patch(element):
    """A linear field imposed on the boundary is reproduced exactly inside, with the exact energy.

    MacNeal and Harder (1985), Finite Elem. Anal. Des. 1, 3–20: `u = 1e-3 (x + y/2)`,
    `v = 1e-3 (y + x/2)`. The interior nodes are solved for; their displacement and the total
    strain energy must equal the continuum values to round-off. Without the Taylor–Beresford–Wilson
    correction the incompatible modes of QM6 would be excited here and the test would fail.
    """
    nu, t = 0.25, 0.001
    mesh = fd.QuadMesh(PATCH_NODES, PATCH_ELEMENTS, orientation="refuse")
    model = fd.FEModel(mesh, element, t, nu)
    k = np.asarray(fd.dense_matrix(model, jnp.ones(5), "stiffness"))
    exact = _nodal(lambda x, y: (1e-3 * (x + y / 2), 1e-3 * (y + x / 2)), PATCH_NODES)
    boundary, inner = np.arange(8), np.arange(8, 16)
    u = exact.copy()
    u[inner] = np.linalg.solve(k[np.ix_(inner, inner)], -k[np.ix_(inner, boundary)] @ exact[boundary])
    np.testing.assert_allclose(u[inner], exact[inner], rtol=0, atol=1e-10 * np.abs(exact).max(),
                               err_msg="interior displacements of a constant strain state")
    eps = 1e-3 * np.array([1.0, 1.0, 1.0])
    energy = 0.5 * eps @ _plane_stress(nu) @ eps * 0.24 * 0.12 * t
    np.testing.assert_allclose(0.5 * u @ k @ u, energy, rtol=1e-10, err_msg="strain energy of the patch")


def test_qm6_bends_exactly_and_q4_locks_on_a_rectangle():
    """Pure bending `u = -kappa x y`, `v = kappa (x^2 + nu y^2) / 2`: energy `1/2 E I kappa^2 L` exactly.

    The field lies in the QM6 space and satisfies its condensation equations, so the condensed
    element energy is exact; Q4 cannot bend without shear and stores more (by about
    `1 + (1 - nu^2)^-1 (dx/dy)^2 / 2` per element here).
    """
    dx, dy, nu, t, kappa = 0.3, 0.1, 0.3, 0.01, 0.01
    xy = np.array([[0.0, -dy / 2], [dx, -dy / 2], [dx, dy / 2], [0.0, dy / 2]])
    u = _nodal(lambda x, y: (-kappa * x * y, kappa * (x * x + nu * y * y) / 2), xy)
    exact = 0.5 * kappa**2 * t * dy**3 / 12 * dx
    k_qm6 = fd.QM6().matrices(xy[None], nu, t)[0][0]
    k_q4 = fd.Q4().matrices(xy[None], nu, t)[0][0]
    np.testing.assert_allclose(0.5 * u @ k_qm6 @ u, exact, rtol=1e-12, err_msg="QM6 pure bending energy")
    assert 0.5 * u @ k_q4 @ u > 2.0 * exact, "Q4 locks in bending"


# --- a slender cantilever --------------------------------------------------------------------------

# The 10 m spin-up beam of Simo and Vu-Quoc (1986): E = 7e10, rho = 2766.67, A = 4e-4, I = 2e-7
# (a rectangle h = sqrt(12 I / A) = 0.0775 m high, b = A / h = 5.16 mm thick), clamped at x = 0.
# Euler–Bernoulli: omega_1 = 1.8751^2 sqrt(E I / (rho A)) / L^2 = 3.9546 rad/s. nu = 0 keeps the
# plane-stress model a beam (a clamped edge with nu > 0 restrains the lateral contraction).
BEAM_L, BEAM_E, BEAM_RHO, BEAM_A, BEAM_I = 10.0, 7e10, 2766.67, 4e-4, 2e-7
BEAM_H = np.sqrt(12 * BEAM_I / BEAM_A)
BEAM_B = BEAM_A / BEAM_H
EULER_BERNOULLI = 1.875104068711961**2 * np.sqrt(BEAM_E * BEAM_I / (BEAM_RHO * BEAM_A)) / BEAM_L**2
# QM6 represents the linear bending stress across the height exactly; what is left is the
# O((L / nx)^2) interpolation error along the beam (1e-4 at nx = 100) and shear and rotary
# inertia of a Timoshenko beam, O((h / L)^2) = 6e-5: 0.1 % is ten times both.
QM6_RTOL = 1e-3


def _cantilever_frequency(element, nx):
    mesh = fd.structured_grid(nx, 2, BEAM_L, BEAM_H)
    model = fd.FEModel(mesh, element, BEAM_B, 0.0)
    clamped = fd.Clamped(range(3))  # nodes (0, j), j = 0..2: the edge x = 0
    layout = fd.ModalReduction(1, clamped).layout(mesh)
    e = jnp.full(mesh.n_elements, BEAM_E)
    rho = jnp.full(mesh.n_elements, BEAM_RHO)
    lam, _ = fd.LanczosModes().solve(model, e, rho, layout, 1)
    return float(np.sqrt(lam[0]))


def test_cantilever_bending_q4_locks_qm6_converges():
    """First frequency of the 10 m cantilever, nx x 2 elements: Q4 locks, QM6 is within 0.1 %.

    The parasitic shear of Q4 stiffens bending by a factor `1 + c (dx / h)^2`, so its error
    falls with order 2 in the element length and is large on elongated elements (the issue saw
    35 %, 10 %, 2.6 % at 100 / 200 / 400 x 2). QM6 has no parasitic shear and is converged at
    the coarsest mesh (error -2.3e-5 .. -3.4e-5). Measured figures: benchmarks/RESULTS.md, "Elements:
    bending of a slender beam, plate with a hole".
    """
    meshes = (100, 200, 400)
    q4_error = []
    for nx in meshes:
        q4, qm6 = _cantilever_frequency(fd.Q4(), nx), _cantilever_frequency(fd.QM6(), nx)
        np.testing.assert_allclose(qm6, EULER_BERNOULLI, rtol=QM6_RTOL, err_msg=f"QM6 cantilever, {nx} x 2")
        q4_error.append(q4 / EULER_BERNOULLI - 1.0)
    assert q4_error[0] > 100 * QM6_RTOL, f"Q4 locks on 100 x 2 elements (error {q4_error[0]:.3f})"
    orders = np.log2(np.asarray(q4_error[:-1]) / np.asarray(q4_error[1:]))
    assert np.all((orders > 1.7) & (orders < 2.2)), f"Q4 locking error falls with order 2: {orders}"


# --- assembly ------------------------------------------------------------------------------------


def test_assembly_dense_matrix_free_and_csc_agree():
    """Global K on a distorted grid: symmetric, PSD, the three rigid motions its null space (a
    numbering error would add mechanisms); M: total mass and first moment of the element densities.
    The matrix-free operator and the host CSC matrices equal the dense assembly (same sums in
    another order: 1e-14)."""
    mesh = fd.structured_grid(7, 4, 1.0, 0.2)
    nodes = np.array(mesh.nodes)
    nodes[:, 0] += 0.02 * np.sin(7.0 * nodes[:, 1])  # non-rectangular elements
    mesh = fd.QuadMesh(nodes, mesh.elements, orientation="refuse")
    model = fd.FEModel(mesh, fd.QM6(), 0.03, 0.3)
    rng = np.random.default_rng(1)
    youngs, rho = jnp.asarray(rng.uniform(0.1, 2.0, (2, mesh.n_elements)))
    k, m = np.asarray(model.stiffness(youngs).todense()), np.asarray(model.mass(rho).todense())
    scale = np.abs(k).max()
    assert np.allclose(k, k.T, rtol=0.0, atol=ROUNDOFF * scale) and np.allclose(m, m.T, rtol=0.0, atol=ROUNDOFF * np.abs(m).max())
    lam = np.linalg.eigvalsh(k)
    assert (np.abs(lam) <= 1e-10 * lam[-1]).sum() == 3 and lam[0] >= -ROUNDOFF * lam[-1], f"null space {lam[:5]}"
    for u in (_nodal(lambda x, y: (1.0, 0.0), nodes), _nodal(lambda x, y: (0.0, 1.0), nodes),
              _nodal(lambda x, y: (-y, x), nodes)):
        assert np.linalg.norm(k @ u) <= ROUNDOFF * np.linalg.norm(k, 2) * np.linalg.norm(u), "K times a rigid motion"
    assert np.linalg.eigvalsh(m)[0] > 0.0, "M is positive definite"
    element_mass = np.asarray(rho) * mesh.element_areas() * 0.03
    ex, ey = np.tile([1.0, 0.0], mesh.n_nodes), np.tile([0.0, 1.0], mesh.n_nodes)
    np.testing.assert_allclose([ex @ m @ ex, ey @ m @ ey], element_mass.sum(), rtol=ROUNDOFF, err_msg="total mass")
    assert abs(ex @ m @ ey) <= ROUNDOFF * element_mass.sum(), "x-y mass coupling"
    np.testing.assert_allclose([ex @ m @ nodes.ravel(), ey @ m @ nodes.ravel()], element_mass @ mesh.element_centroids(),
                               rtol=ROUNDOFF, err_msg="first moment")
    v = jnp.asarray(rng.normal(size=(mesh.n_dof, 3)))
    np.testing.assert_allclose(model.stiffness(youngs) @ v, k @ v, rtol=0, atol=1e-14 * scale * np.abs(v).max() * 8,
                               err_msg="matrix-free K @ V")
    fixed = (0, 1, 7)
    free = np.setdiff1d(np.arange(mesh.n_dof), fixed)
    k_ff, m_ff = fd.csc_matrices(mesh, np.asarray(youngs), np.asarray(rho), np.asarray(model.unit_stiffness),
                                 np.asarray(model.unit_mass), fixed)
    np.testing.assert_allclose(k_ff.toarray(), k[np.ix_(free, free)], rtol=0, atol=1e-14 * scale, err_msg="CSC K_ff")
    np.testing.assert_allclose(m_ff.toarray(), m[np.ix_(free, free)], rtol=0, atol=1e-14 * np.abs(m).max(),
                               err_msg="CSC M_ff")
    with pytest.raises(ValueError, match="cannot multiply"):
        _ = model.stiffness(youngs) @ jnp.ones(mesh.n_dof + 1)


# --- beam theory --------------------------------------------------------------------------------------

# A slender steel-like strip, 200 x 2 Q4 elements. Q4 bends with parasitic shear, an error of order
# 2 (dx / 2 h)^2 / (1 + nu) in stiffness, so the mesh is fine along the length; nu = 0 removes the
# plane-stress anticlastic stiffening that two elements through the height would add (about 2.5 %).
# Discretisation error allowed against Euler–Bernoulli: 2 %.
STRIP = dict(length=1.0, height=0.03, thickness=0.01)
STRIP_E, STRIP_RHO, BEAM_RTOL = 2.0e11, 7800.0, 0.02


@pytest.fixture(scope="module")
def strip():
    mesh = fd.structured_grid(200, 2, STRIP["length"], STRIP["height"])
    model = fd.FEModel(mesh, fd.Q4(), STRIP["thickness"], 0.0)
    youngs, rho = np.full(mesh.n_elements, STRIP_E), np.full(mesh.n_elements, STRIP_RHO)
    second_moment = STRIP["thickness"] * STRIP["height"] ** 3 / 12.0
    return mesh, model, youngs, rho, second_moment


def test_cantilever_tip_deflection_matches_beam_theory(strip):
    mesh, model, youngs, rho, second_moment = strip
    fixed = tuple(d for j in range(3) for d in (2 * mesh.node(0, j), 2 * mesh.node(0, j) + 1))
    free = np.setdiff1d(np.arange(mesh.n_dof), fixed)
    k, _ = fd.csc_matrices(mesh, youngs, rho, np.asarray(model.unit_stiffness), np.asarray(model.unit_mass), fixed)
    load = 1.0e3
    f = np.zeros(mesh.n_dof)
    for j, w in enumerate((0.25, 0.5, 0.25)):  # the tip load on the end edge, consistent weights
        f[2 * mesh.node(mesh.nx, j) + 1] = load * w
    u = np.zeros(mesh.n_dof)
    u[free] = scipy.sparse.linalg.spsolve(k, f[free])
    exact = load * STRIP["length"] ** 3 / (3.0 * STRIP_E * second_moment)
    np.testing.assert_allclose(u[2 * mesh.node(mesh.nx, 1) + 1], exact, rtol=BEAM_RTOL,
                               err_msg="cantilever tip deflection P L^3 / (3 E I)")


def test_hinged_beam_frequencies_match_beam_theory(strip):
    """Hinged–hinged bending frequencies `f_n = n^2 pi / (2 L^2) sqrt(E I / (rho A))`, by the library's
    modal reduction (the paper's reference conditions, [`HingedHinged`][])."""
    mesh, model, youngs, rho, second_moment = strip
    a, b = fd.rod_joint_nodes(mesh.nx, mesh.ny)
    reduction = fd.ModalReduction(4, fd.HingedHinged(a, b), solver=fd.LanczosModes())
    computed = np.asarray(reduction(model, jnp.asarray(youngs), jnp.asarray(rho)).frequencies)
    area = STRIP["thickness"] * STRIP["height"]
    for n in (1, 2, 3):
        exact = n**2 * np.pi / (2.0 * STRIP["length"] ** 2) * np.sqrt(STRIP_E * second_moment / (STRIP_RHO * area))
        # B slides along x, so axial modes are in the spectrum too: match bending modes by value.
        nearest = computed[np.argmin(np.abs(computed - exact))]
        np.testing.assert_allclose(nearest, exact, rtol=BEAM_RTOL, err_msg=f"hinged-hinged bending frequency {n}")
