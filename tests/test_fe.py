"""The finite element model: Q4 element, mesh numbering, assembly, SIMP, and beam theory."""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

import ffr_jax
from ffr_jax._fe import q4_element_matrices

# Round-off level for quantities that vanish exactly in exact arithmetic, relative to their scale.
ROUNDOFF = 1e-12
# Discretisation error allowed against Euler–Bernoulli beam theory.
BEAM_RTOL = 0.02

ELEMENT_SHAPES = [(0.01, 0.01, 0.3, 0.01), (0.02, 0.005, 0.3, 0.01), (0.003, 0.011, 0.0, 0.2), (1.0, 2.0, 0.45, 1.0)]


def _corners(dx, dy):
    """Corner coordinates of the element `[0, dx] x [0, dy]`, counter-clockwise from the lower left."""
    return np.array([[0.0, 0.0], [dx, 0.0], [dx, dy], [0.0, dy]])


def _nodal(field, xy):
    """Interleaved nodal vector `(u_x, u_y)` per node of a displacement field `field(x, y) -> (u, v)`."""
    return np.stack([np.asarray(field(x, y), dtype=float) for x, y in xy]).ravel()


def _rigid_motions(xy):
    """The three rigid-body motions of a planar body: two translations and an infinitesimal rotation."""
    return [
        _nodal(lambda x, y: (1.0, 0.0), xy),
        _nodal(lambda x, y: (0.0, 1.0), xy),
        _nodal(lambda x, y: (-y, x), xy),
    ]


def _plane_stress(nu):
    return np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)


# --- one element ----------------------------------------------------------------------------


@pytest.mark.parametrize("dx, dy, nu, t", ELEMENT_SHAPES)
def test_q4_rigid_body_motions_store_no_strain_energy(dx, dy, nu, t):
    k, _ = q4_element_matrices(dx, dy, nu, t)
    for u in _rigid_motions(_corners(dx, dy)):
        scale = np.linalg.norm(k, 2) * (u @ u)
        assert abs(u @ k @ u) <= ROUNDOFF * scale, "strain energy of a rigid-body motion"
        assert np.linalg.norm(k @ u) <= ROUNDOFF * np.linalg.norm(k, 2) * np.linalg.norm(u), "force of a rigid motion"


@pytest.mark.parametrize("dx, dy, nu, t", ELEMENT_SHAPES)
def test_q4_stiffness_symmetric_psd_with_three_zero_eigenvalues(dx, dy, nu, t):
    k, _ = q4_element_matrices(dx, dy, nu, t)
    assert np.allclose(k, k.T, rtol=0.0, atol=ROUNDOFF * np.abs(k).max()), "element stiffness symmetry"
    lam = np.linalg.eigvalsh(k)
    zero = np.abs(lam) <= 1e-10 * lam[-1]
    assert lam[0] >= -ROUNDOFF * lam[-1], "element stiffness is positive semi-definite"
    assert zero.sum() == 3, f"element stiffness has {zero.sum()} zero eigenvalues, expected 3: {lam}"
    # Full 2x2 integration: no hourglass modes, so the five deformation modes are well separated from zero.
    assert lam[3] >= 1e-4 * lam[-1], "smallest deformation eigenvalue of the element stiffness"


@pytest.mark.parametrize("dx, dy, nu, t", ELEMENT_SHAPES)
def test_q4_constant_strain_patch(dx, dy, nu, t):
    """A linear displacement field gives exactly the continuum energy `1/2 eps^T D eps V` (for `E = 1`)."""
    k, _ = q4_element_matrices(dx, dy, nu, t)
    rng = np.random.default_rng(0)
    a, b, c, d = rng.normal(size=4)
    u = _nodal(lambda x, y: (a * x + b * y, c * x + d * y), _corners(dx, dy))
    eps = np.array([a, d, b + c])
    exact = 0.5 * eps @ _plane_stress(nu) @ eps * dx * dy * t
    np.testing.assert_allclose(0.5 * u @ k @ u, exact, rtol=ROUNDOFF, err_msg="energy of a constant strain state")


@pytest.mark.parametrize("dx, dy, nu, t", ELEMENT_SHAPES)
def test_q4_consistent_mass(dx, dy, nu, t):
    _, m = q4_element_matrices(dx, dy, nu, t)
    volume = dx * dy * t
    # Exact consistent mass of a bilinear rectangle, nodes counter-clockwise, per displacement component.
    scalar = volume / 36.0 * np.array(
        [[4.0, 2.0, 1.0, 2.0], [2.0, 4.0, 2.0, 1.0], [1.0, 2.0, 4.0, 2.0], [2.0, 1.0, 2.0, 4.0]]
    )
    np.testing.assert_allclose(m[0::2, 0::2], scalar, rtol=ROUNDOFF, err_msg="x-x block of the element mass")
    np.testing.assert_allclose(m[1::2, 1::2], scalar, rtol=ROUNDOFF, err_msg="y-y block of the element mass")
    assert np.all(m[0::2, 1::2] == 0.0), "x-y coupling of the element mass"
    ex, ey = np.tile([1.0, 0.0], 4), np.tile([0.0, 1.0], 4)
    np.testing.assert_allclose(ex @ m @ ex, volume, rtol=ROUNDOFF, err_msg="element mass (rho = 1)")
    np.testing.assert_allclose(ey @ m @ ey, volume, rtol=ROUNDOFF, err_msg="element mass (rho = 1)")


# --- mesh and assembly ----------------------------------------------------------------------


def test_mesh_numbering_matches_the_documented_layout():
    mesh = ffr_jax.RodMesh(5, 4, length=2.0, height=0.4)
    xy = mesh.node_coordinates()
    for i in range(mesh.nx + 1):
        for j in range(mesh.ny + 1):
            n = i * (mesh.ny + 1) + j
            np.testing.assert_allclose(xy[n], [i * 2.0 / 5, -0.2 + j * 0.1], atol=1e-15, err_msg=f"node ({i}, {j})")
    dofs = mesh.element_dofs()
    centres = mesh.element_centres()
    for i in range(mesh.nx):
        for j in range(mesh.ny):
            e = j * mesh.nx + i
            nodes = dofs[e, 0::2] // 2
            np.testing.assert_array_equal(dofs[e, 1::2], 2 * nodes + 1)
            x0, y0 = i * mesh.dx, -0.2 + j * mesh.dy
            np.testing.assert_allclose(xy[nodes], _corners(mesh.dx, mesh.dy) + [x0, y0], atol=1e-15,
                                       err_msg=f"corners of element ({i}, {j})")
            np.testing.assert_allclose(centres[e], [x0 + mesh.dx / 2, y0 + mesh.dy / 2], atol=1e-15)
    np.testing.assert_allclose(xy[mesh.node_a], [0.0, 0.0], atol=1e-15, err_msg="joint point A")
    np.testing.assert_allclose(xy[mesh.node_b], [2.0, 0.0], atol=1e-15, err_msg="joint point B")


def test_assembled_matrices():
    """Global K: symmetric, PSD, exactly the three rigid motions in its null space (a numbering error
    would add mechanisms). Global M: total mass and first moment of the element densities."""
    mesh = ffr_jax.RodMesh(7, 4, length=1.0, height=0.2, thickness=0.03)
    rng = np.random.default_rng(1)
    youngs = jnp.asarray(rng.uniform(0.1, 2.0, mesh.n_elements))
    rho = jnp.asarray(rng.uniform(0.1, 2.0, mesh.n_elements))
    k = np.asarray(ffr_jax.stiffness_matrix(mesh, youngs))
    m = np.asarray(ffr_jax.mass_matrix(mesh, rho))
    scale = np.abs(k).max()
    assert np.allclose(k, k.T, rtol=0.0, atol=ROUNDOFF * scale), "global stiffness symmetry"
    assert np.allclose(m, m.T, rtol=0.0, atol=ROUNDOFF * np.abs(m).max()), "global mass symmetry"
    lam = np.linalg.eigvalsh(k)
    assert (np.abs(lam) <= 1e-10 * lam[-1]).sum() == 3, f"global stiffness null space: {lam[:5]}"
    assert lam[0] >= -ROUNDOFF * lam[-1]
    xy = mesh.node_coordinates()
    for u in _rigid_motions(xy):
        assert np.linalg.norm(k @ u) <= ROUNDOFF * np.linalg.norm(k, 2) * np.linalg.norm(u), "K times rigid motion"
    assert np.linalg.eigvalsh(m)[0] > 0.0, "global mass is positive definite"

    element_mass = np.asarray(rho) * mesh.dx * mesh.dy * mesh.thickness
    ex = np.tile([1.0, 0.0], mesh.n_nodes)
    ey = np.tile([0.0, 1.0], mesh.n_nodes)
    np.testing.assert_allclose(ex @ m @ ex, element_mass.sum(), rtol=ROUNDOFF, err_msg="total mass (x)")
    np.testing.assert_allclose(ey @ m @ ey, element_mass.sum(), rtol=ROUNDOFF, err_msg="total mass (y)")
    assert abs(ex @ m @ ey) <= ROUNDOFF * element_mass.sum(), "x-y mass coupling"
    c = xy.ravel()
    np.testing.assert_allclose([ex @ m @ c, ey @ m @ c], element_mass @ mesh.element_centres(), rtol=ROUNDOFF,
                               err_msg="first moment")


def test_uniform_mass_is_rho_times_volume():
    mesh = ffr_jax.RodMesh(10, 2)
    rho0 = 8750.0
    m = ffr_jax.mass_matrix(mesh, jnp.full(mesh.n_elements, rho0))
    ex = jnp.tile(jnp.array([1.0, 0.0]), mesh.n_nodes)
    np.testing.assert_allclose(ex @ m @ ex, rho0 * mesh.length * mesh.height * mesh.thickness, rtol=ROUNDOFF)


# --- SIMP and design layout -------------------------------------------------------------------


def test_simp_law():
    simp = ffr_jax.SIMP()
    x = jnp.array([0.01, 0.05, 0.0999, 0.1, 0.3, 1.0])
    rho_low = simp.mass_factor * x**simp.mass_penalty * simp.density
    np.testing.assert_allclose(simp.densities(x), jnp.where(x < 0.1, rho_low, x * simp.density), rtol=ROUNDOFF)
    np.testing.assert_allclose(simp.youngs(x), x**3 * simp.youngs_modulus, rtol=ROUNDOFF)
    # eq. 47 with c = 1e5, q = 6 is continuous at the switch x = 0.1: the two branches agree there
    # (c 0.1^6 = 0.1), and just below it the density differs from rho(0.1) by at most its largest
    # slope on [0.1 - eps, 0.1], 6 c 0.1^5 rho0 = 6 rho0, times eps (measured: that to 4 digits),
    # plus the round-off of two evaluations of size 0.1 rho0; a jump would be a fraction of 0.1 rho0.
    np.testing.assert_allclose(simp.mass_factor * 0.1**simp.mass_penalty, 0.1, rtol=ROUNDOFF,
                               err_msg="the two branches of eq. 47 meet at x = 0.1")
    eps = 1e-9
    below, above = simp.densities(jnp.array([0.1 - eps, 0.1]))
    np.testing.assert_allclose(below, above, rtol=0, atol=6 * simp.density * eps + ROUNDOFF * simp.density,
                               err_msg="density continuity at x = 0.1")


def test_design_layout_puts_solid_interfaces_and_orders_row_major():
    design = ffr_jax.RodDesign(ffr_jax.RodMesh(6, 4), ffr_jax.SIMP())
    nx, ny = 6, 4
    assert design.n_design == ny * (nx - 2)
    x = jnp.linspace(0.2, 0.9, design.n_design)
    xe = np.asarray(design.element_densities(x))
    grid = np.asarray(x).reshape(ny, nx - 2)
    for j in range(ny):
        for i in range(nx):
            expected = 1.0 if i in (0, nx - 1) else grid[j, i - 1]
            assert xe[j * nx + i] == expected, f"element ({i}, {j})"
    np.testing.assert_allclose(design.design_centres(),
                               design.mesh.element_centres().reshape(ny, nx, 2)[:, 1:-1].reshape(-1, 2))


# --- beam theory ------------------------------------------------------------------------------

# A slender steel-like strip. Q4 elements bend with parasitic shear, an error of order
# 2 (dx / 2 h)^2 / (1 + nu) in stiffness, so the mesh is fine along the length; nu = 0 removes the
# plane-stress anticlastic stiffening that two elements through the height would add (about 2.5 %).
BEAM = dict(length=1.0, height=0.03, thickness=0.01, poisson=0.0)
BEAM_NX, BEAM_NY = 200, 2
E_BEAM, RHO_BEAM = 2.0e11, 7800.0


@pytest.fixture(scope="module")
def beam():
    mesh = ffr_jax.RodMesh(BEAM_NX, BEAM_NY, **BEAM)
    k = ffr_jax.stiffness_matrix(mesh, jnp.full(mesh.n_elements, E_BEAM))
    m = ffr_jax.mass_matrix(mesh, jnp.full(mesh.n_elements, RHO_BEAM))
    second_moment = BEAM["thickness"] * BEAM["height"] ** 3 / 12.0
    area = BEAM["thickness"] * BEAM["height"]
    return mesh, k, m, second_moment, area


def test_cantilever_tip_deflection_matches_beam_theory(beam):
    mesh, k, _, second_moment, _ = beam
    clamped = [mesh.node(0, j) for j in range(mesh.ny + 1)]
    fixed = np.array([2 * n + d for n in clamped for d in (0, 1)])
    free = np.setdiff1d(np.arange(mesh.n_dof), fixed)
    load = 1.0e3
    weights = np.ones(mesh.ny + 1)
    weights[[0, -1]] = 0.5
    f = np.zeros(mesh.n_dof)
    for j, w in enumerate(weights / weights.sum()):
        f[2 * mesh.node(mesh.nx, j) + 1] = load * w
    u = np.zeros(mesh.n_dof)
    u[free] = scipy.sparse.linalg.spsolve(scipy.sparse.csc_matrix(np.asarray(k)[np.ix_(free, free)]), f[free])
    tip = u[2 * mesh.node_b + 1]
    exact = load * mesh.length**3 / (3.0 * E_BEAM * second_moment)
    np.testing.assert_allclose(tip, exact, rtol=BEAM_RTOL, err_msg="cantilever tip deflection P L^3 / (3 E I)")


def test_hinged_beam_frequencies_match_beam_theory(beam):
    """Hinged–hinged bending frequencies `f_n = n^2 pi / (2 L^2) sqrt(E I / (rho A))`.

    The eigenvalues come from SciPy (sparse shift-invert, lowest few), which makes this a check of the
    FE matrices; `hinged_modes` itself is checked against the reference rod and in `test_modes.py`.
    """
    mesh, k, m, second_moment, area = beam
    a, b = mesh.node_a, mesh.node_b
    free = np.setdiff1d(np.arange(mesh.n_dof), [2 * a, 2 * a + 1, 2 * b + 1])
    k = scipy.sparse.csc_matrix(np.asarray(k)[np.ix_(free, free)])
    m = scipy.sparse.csc_matrix(np.asarray(m)[np.ix_(free, free)])
    lam = np.sort(scipy.sparse.linalg.eigsh(k, k=4, M=m, sigma=0.0, which="LM", return_eigenvectors=False))
    computed = np.sqrt(lam) / (2.0 * np.pi)
    for n in (1, 2, 3):
        exact = n**2 * np.pi / (2.0 * mesh.length**2) * np.sqrt(E_BEAM * second_moment / (RHO_BEAM * area))
        # B slides along x, so axial modes are in the spectrum too: match bending modes by value.
        nearest = computed[np.argmin(np.abs(computed - exact))]
        np.testing.assert_allclose(nearest, exact, rtol=BEAM_RTOL, err_msg=f"hinged-hinged bending frequency {n}")


# --- the reference rod ------------------------------------------------------------------------

# REFERENCE_CASE §2, to the digits quoted there (a half unit of the last quoted digit).
REFERENCE_FREQUENCIES = [(32.6, 0.05), (128.0, 0.5), (281.0, 0.5), (291.0, 0.5), (483.0, 0.5), (726.0, 0.5)]


def _reference_frequencies_fe_only():
    """`case.frequencies` of the reference case, by the same stages without building the scene."""
    design = ffr_jax.RodDesign(ffr_jax.RodMesh(100, 6), ffr_jax.SIMP())
    xe = design.element_densities(design.check(design.initial_design(0.5)))
    k = ffr_jax.stiffness_matrix(design.mesh, design.material.youngs(xe))
    m = ffr_jax.mass_matrix(design.mesh, design.material.densities(xe))
    a, b = design.mesh.node_a, design.mesh.node_b
    return ffr_jax.hinged_modes(k, m, (2 * a, 2 * a + 1, 2 * b + 1), 6).frequencies


def _check_reference(frequencies):
    for n, (f, (quoted, half_digit)) in enumerate(zip(np.asarray(frequencies), REFERENCE_FREQUENCIES), 1):
        assert abs(f - quoted) <= half_digit, f"reference frequency {n}: {f:.4f} Hz, quoted {quoted} Hz"


def test_reference_rod_frequencies():
    _check_reference(_reference_frequencies_fe_only())


@pytest.mark.slow
def test_reference_case_frequencies():
    case = ffr_jax.cases.slider_crank(100, 6, 6)
    _check_reference(case.frequencies(case.initial_design(0.5)))
