"""Standard input data of the rod against independent evaluations, the body kinetic energy, the
invariance of everything under `Phi -> Phi Q`, and the geometric stiffness of a spinning rod.

The brute-force route integrates over the mesh element by element with 3x3 Gauss quadrature and
the bilinear shape functions, using only the layout of the structured grid (node `(i, j)` at
index `i (ny + 1) + j`, element `(i, j)` at `j nx + i`): no library matrix is used.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from helpers import assert_close_relative, random_design, random_orthogonal, rotation, small_case, tree_allclose

import ffr_jax
import ffr_jax._design as fd
from ffr_jax._dynamics._body_dynamics import (
    body_inertia_and_elastic_forces,
    body_kinetic_energy,
    body_mass_matrix,
    marker_position,
)

# Two routes that differ only by summation order agree to round-off.
BRUTE_RTOL = 1e-12
FIELDS = ("mass", "first_moment", "modal_moment", "inertia", "inertia_q", "modal_mass", "coupling_0", "coupling",
          "modal_stiffness")


def _quadrature_body_data(case, x, modes):
    """Every integral of the body-data table by Gauss quadrature over the elements (NumPy)."""
    mesh, material = case.mesh, case.material
    nx, ny, dx, dy, t = mesh.nx, mesh.ny, mesh.dx, mesh.dy, case.design.model.thickness
    xe = np.asarray(case.design.element_densities(x))
    rho = np.asarray(material.densities(jnp.asarray(xe)))
    youngs = np.asarray(material.youngs(jnp.asarray(xe)))
    nu = case.design.model.poisson
    d = np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)
    phi_nodes = np.asarray(modes).reshape(mesh.n_nodes, 2, -1)
    n_q = phi_nodes.shape[-1]
    gauss, weights = np.polynomial.legendre.leggauss(3)
    corner = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    perp = np.array([[0.0, -1.0], [1.0, 0.0]])

    acc = dict(mass=0.0, first_moment=np.zeros(2), modal_moment=np.zeros((2, n_q)), inertia=0.0,
               inertia_q=np.zeros(n_q), modal_mass=np.zeros((n_q, n_q)), coupling_0=np.zeros(n_q),
               coupling=np.zeros((n_q, n_q)), modal_stiffness=np.zeros((n_q, n_q)))
    for j in range(ny):
        for i in range(nx):
            e = j * nx + i
            nodes = [ii * (ny + 1) + jj for ii, jj in ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1))]
            x0, y0 = i * dx, -0.5 * mesh.height + j * dy
            phi_e = phi_nodes[nodes]  # (4, 2, n_q)
            for xi, wx in zip(gauss, weights):
                for eta, wy in zip(gauss, weights):
                    n = 0.25 * (1 + corner[:, 0] * xi) * (1 + corner[:, 1] * eta)
                    dn_dx = 0.25 * corner[:, 0] * (1 + corner[:, 1] * eta) * 2.0 / dx
                    dn_dy = 0.25 * corner[:, 1] * (1 + corner[:, 0] * xi) * 2.0 / dy
                    w = wx * wy * dx * dy / 4.0 * t
                    c = np.array([x0 + (1 + xi) * dx / 2, y0 + (1 + eta) * dy / 2])
                    phi = np.einsum("a,aiq->iq", n, phi_e)  # (2, n_q)
                    strain = np.stack([dn_dx @ phi_e[:, 0], dn_dy @ phi_e[:, 1],
                                       dn_dy @ phi_e[:, 0] + dn_dx @ phi_e[:, 1]])  # (3, n_q)
                    dm = rho[e] * w
                    acc["mass"] += dm
                    acc["first_moment"] += dm * c
                    acc["modal_moment"] += dm * phi
                    acc["inertia"] += dm * c @ c
                    acc["inertia_q"] += dm * phi.T @ c
                    acc["modal_mass"] += dm * phi.T @ phi
                    acc["coupling_0"] += dm * phi.T @ perp @ c
                    acc["coupling"] += dm * phi.T @ perp @ phi
                    acc["modal_stiffness"] += youngs[e] * w * strain.T @ d @ strain
    return acc


def _nodal_model(case, x, modes):
    """The FE body written out node by node: `r_n(y_b)` interleaved, and the consistent mass `M`."""
    _, m = case.fe_matrices(x)
    c = jnp.asarray(case.mesh.nodes)
    phi = jnp.asarray(modes).reshape(case.mesh.n_nodes, 2, -1)

    def positions(y_b):
        r, theta, q = y_b[:2], y_b[2], y_b[3:]
        u = c + jnp.einsum("niq,q->ni", phi, q)
        return (r[None, :] + u @ rotation(theta).T).ravel()

    @jax.jit
    def kinetic_energy(y_b, z_b):
        _, rdot = jax.jvp(positions, (y_b,), (z_b,))
        return 0.5 * rdot @ m @ rdot

    return positions, kinetic_energy


def _random_state(n_q, seed):
    """Random `(y_b, z_b)`: translations and rotation of order one, modal amplitudes giving
    deformations of a few percent of the rod length."""
    rng = np.random.default_rng(seed)
    y = np.concatenate([rng.normal(size=2), rng.uniform(-np.pi, np.pi, 1), 0.05 * rng.normal(size=n_q)])
    z = np.concatenate([rng.normal(size=3), 5.0 * rng.normal(size=n_q)])
    return jnp.asarray(y), jnp.asarray(z)


@pytest.fixture(scope="module")
def flexible():
    """`(case, design, modes, body data)` at a random design that also visits the low-density SIMP branch."""
    case = small_case()
    rng = np.random.default_rng(3)
    x = jnp.asarray(rng.uniform(0.02, 1.0, case.n_design))
    modes = case.modes(x).modes
    return case, x, modes, case.body_data(x)


def test_body_data_equals_element_quadrature(flexible):
    case, x, modes, data = flexible
    brute = _quadrature_body_data(case, x, modes)
    # K_qq = Phi^T K Phi = diag(lambda) is a sum whose terms reach lambda_max: either route's round-off is
    # at most n eps (|Phi|^T |K| |Phi|)_max (Higham, Accuracy and Stability of Numerical Algorithms,
    # Sect. 3.5), 4.4e3 times max |K_qq| here (BRUTE_RTOL, 1e-12, was 0.1 of the observed 1e-13). The
    # other fields have no such cancellation (factor 1.0; measured 1e-15).
    k = np.asarray(case.fe_matrices(x)[0])
    phi = np.abs(np.asarray(modes))
    cancellation = (phi.T @ np.abs(k) @ phi).max() / np.abs(np.asarray(data.modal_stiffness)).max()
    stiffness_rtol = k.shape[0] * np.finfo(float).eps * cancellation
    for field in FIELDS:
        rtol = stiffness_rtol if field == "modal_stiffness" else BRUTE_RTOL
        assert_close_relative(getattr(data, field), brute[field], rtol, field)


def test_body_data_structure(flexible):
    """Mass normalisation, skew-symmetric G, symmetric K_qq: consequences of the definitions."""
    _, _, _, data = flexible
    n_q = data.n_modes
    assert_close_relative(data.modal_mass, np.eye(n_q), BRUTE_RTOL, "modal_mass = I (mass-normalised modes)")
    assert_close_relative(data.coupling, -data.coupling.T, BRUTE_RTOL, "coupling G is skew-symmetric")
    assert_close_relative(data.modal_stiffness, data.modal_stiffness.T, BRUTE_RTOL, "modal_stiffness symmetry")


@pytest.mark.parametrize("seed", [0, 1])
def test_kinetic_energy_equals_nodal_sum(flexible, seed):
    """`T(y_b, z_b)` from the body data equals `1/2 rdot_n^T M rdot_n` over all mesh nodes, and
    `M_b` is its Hessian in the velocities."""
    case, x, modes, data = flexible
    _, kinetic_energy = _nodal_model(case, x, modes)
    y, z = _random_state(data.n_modes, seed)
    np.testing.assert_allclose(body_kinetic_energy(data, y, z), kinetic_energy(y, z), rtol=BRUTE_RTOL,
                               err_msg="kinetic energy")
    hessian = jax.jit(jax.hessian(kinetic_energy, argnums=1))(y, z)
    assert_close_relative(body_mass_matrix(data, y), hessian, BRUTE_RTOL, "body mass matrix M_b(y_b)")


@functools.partial(jax.jit, static_argnums=0)
def _lagrange_forces(kinetic_energy, stiffness, y, z):
    """`-(d/dt dT/dz - M zdot) + dT/dy - dV/dy`: quadratic-velocity and elastic forces by Lagrange."""
    def momentum(y_):
        return jax.grad(kinetic_energy, argnums=1)(y_, z)

    _, momentum_rate = jax.jvp(momentum, (y,), (z,))
    elastic = jnp.concatenate([jnp.zeros(3), stiffness @ y[3:]])
    return -momentum_rate + jax.grad(kinetic_energy, argnums=0)(y, z) - elastic


def test_quadratic_velocity_forces_follow_from_lagrange(flexible):
    case, x, modes, data = flexible
    _, kinetic_energy = _nodal_model(case, x, modes)
    y, z = _random_state(data.n_modes, 7)
    expected = _lagrange_forces(kinetic_energy, data.modal_stiffness, y, z)
    assert_close_relative(body_inertia_and_elastic_forces(data, y, z), expected, 1e-11,
                          "-h_omega - h_e against Lagrange's equations")


# --- rigid body -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rigid():
    """A solid rod (x = 1) as a rigid body, with its nodal model (zero modes)."""
    case = small_case()
    x = jnp.ones(case.n_design)
    flex = case.body_data(x)
    data = ffr_jax.rigid_body_data(flex.mass, flex.first_moment, flex.inertia, flex.marker_positions)
    no_modes = jnp.zeros((case.mesh.n_dof, 0))
    return case, x, no_modes, flex, data


def test_rigid_rectangle_integrals(rigid):
    """Uniform rectangle `[0, L] x [-h/2, h/2]`: `m = rho L h t`, `s0 = m (L/2, 0)`,
    `J0 = m (L^2/3 + h^2/12)` about A (the consistent mass integrates these exactly)."""
    case, _, _, flex, data = rigid
    mesh = case.mesh
    m = case.material.density * mesh.length * mesh.height * case.design.model.thickness
    np.testing.assert_allclose(flex.mass, m, rtol=BRUTE_RTOL, err_msg="mass")
    np.testing.assert_allclose(flex.first_moment, [m * mesh.length / 2, 0.0], rtol=BRUTE_RTOL,
                               atol=BRUTE_RTOL * m * mesh.length, err_msg="first moment")
    np.testing.assert_allclose(flex.inertia, m * (mesh.length**2 / 3 + mesh.height**2 / 12), rtol=BRUTE_RTOL,
                               err_msg="polar inertia about A")
    assert data.n_modes == 0
    for field in ("modal_moment", "inertia_q", "modal_mass", "coupling_0", "coupling", "modal_stiffness",
                  "marker_modes"):
        assert getattr(data, field).size == 0, field


def test_rigid_body_behaves_like_flexible_without_modes(rigid):
    case, x, no_modes, flex, data = rigid
    _, kinetic_energy = _nodal_model(case, x, no_modes)
    y, z = _random_state(0, 11)
    np.testing.assert_allclose(body_kinetic_energy(data, y, z), kinetic_energy(y, z), rtol=BRUTE_RTOL,
                               err_msg="rigid kinetic energy")
    y_flex = jnp.concatenate([y, jnp.zeros(flex.n_modes)])
    assert_close_relative(body_mass_matrix(data, y), body_mass_matrix(flex, y_flex)[:3, :3], BRUTE_RTOL,
                          "rigid mass matrix = rigid block of the flexible one at q = 0")
    expected = _lagrange_forces(kinetic_energy, data.modal_stiffness, y, z)
    assert_close_relative(body_inertia_and_elastic_forces(data, y, z), expected, 1e-11,
                          "rigid centrifugal forces against Lagrange's equations")
    for marker in (0, 1):
        np.testing.assert_allclose(marker_position(data, marker, y), marker_position(flex, marker, y_flex),
                                   rtol=BRUTE_RTOL, atol=1e-15, err_msg=f"rigid marker {marker}")


def test_flexible_body_data_with_zero_modes_is_rigid_body_data(rigid):
    case, x, no_modes, _, data = rigid
    k, m = case.design.matrices(x)  # the operators case.body_data used, so the sums are the same
    zero_mode_data = fd.body_data(case.design.model, k, m, no_modes, case.marker_nodes)
    assert tree_allclose(zero_mode_data, data, rtol=BRUTE_RTOL), "flexible body data with n_q = 0"


# --- markers ------------------------------------------------------------------------------------


def test_markers_are_the_joint_points(flexible):
    case, x, modes, data = flexible
    mesh = case.mesh
    np.testing.assert_allclose(data.marker_positions, [[0.0, 0.0], [mesh.length, 0.0]], atol=1e-15,
                               err_msg="markers A and B in body coordinates")
    rows = np.asarray(modes).reshape(mesh.n_nodes, 2, -1)
    node_a, node_b = case.marker_nodes
    np.testing.assert_array_equal(data.marker_modes[0], rows[node_a], err_msg="marker A rows")
    np.testing.assert_array_equal(data.marker_modes[1], rows[node_b], err_msg="marker B rows")
    # REFERENCE_CASE §2: A has no elastic displacement, B moves along the frame's x-axis only.
    assert np.all(np.asarray(data.marker_modes[0]) == 0.0), "elastic displacement of A"
    assert np.all(np.asarray(data.marker_modes[1, 1]) == 0.0), "transverse elastic displacement of B"
    positions, _ = _nodal_model(case, x, modes)
    y, _ = _random_state(data.n_modes, 5)
    r = positions(y).reshape(-1, 2)
    for marker, node in enumerate(case.marker_nodes):
        np.testing.assert_allclose(marker_position(data, marker, y), r[node], rtol=BRUTE_RTOL,
                                   err_msg=f"inertial position of marker {marker}")


# --- invariance under Phi -> Phi Q ----------------------------------------------------------------
# Equalities that hold in exact arithmetic between quantities computed from the same eigen-solution
# (body data of Phi and of Phi Q, the quadratic forms of the motion): round-off of a few operations on
# well-scaled numbers, ~1e-15..1e-13 measured; far below this bound, and far above it for any error.
EIG_RTOL = 1e-10
# An eigen-solution itself is accurate only relative to the largest eigenvalue of the pencil: a
# backward-stable symmetric-definite solver (Cholesky reduction to C = L^-1 K L^-T, then a symmetric
# eigensolver: the library's and LAPACK's dsygvd alike) returns every eigenvalue to
# p(n) eps ||C||_2 = p(n) eps lambda_max in absolute terms (Golub & Van Loan, Matrix Computations, 4th
# ed., Sects. 8.4 and 8.7). On the 12 x 2 rod lambda_max / lambda_1 = 3e6, so the lowest eigenvalue is
# known to ~1e-10 relative only: a relative bound of 1e-10 on it is a coin toss (issue 11). p(n) is
# taken as n (the textbook worst case); measured: 0.1-0.7 eps lambda_max.
EIG_EPS = np.finfo(float).eps


def _eigen_accuracy(case, x):
    """`n eps lambda_max` of the free hinged-hinged pencil at design `x` (see EIG_EPS)."""
    k, m = (np.asarray(a) for a in case.fe_matrices(x))
    free = np.setdiff1d(np.arange(case.mesh.n_dof), case.fixed_dofs)
    lam_max = scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)], eigvals_only=True)[-1]
    return free.size * EIG_EPS * lam_max


def test_rotating_the_retained_basis_changes_no_invariant():
    """Sign flips and an orthogonal `Q`: body data transform covariantly, and energies, forces and
    marker positions of the motion with `q -> Q^T q` are unchanged."""
    case = small_case()
    x = random_design(case, 6)
    k, m = case.fe_matrices(x)
    basis = case.modes(x)
    phi = basis.modes
    q = jnp.asarray(random_orthogonal(case.n_modes, 7))
    flips = jnp.diag(jnp.array([1.0, -1.0, -1.0, 1.0]))
    model = case.design.model
    accuracy = _eigen_accuracy(case, x)
    for label, rot in (("sign flips", flips), ("orthogonal Q", q)):
        a = fd.body_data(model, k, m, phi, case.marker_nodes)
        b = fd.body_data(model, k, m, phi @ rot, case.marker_nodes)
        for field in ("mass", "first_moment", "inertia"):
            assert_close_relative(getattr(b, field), getattr(a, field), 1e-14, f"{field} ({label})")
        # Covariance of every modal field: S1 Q, Q^T j1, Q^T M_qq Q, Q^T G0, Q^T G Q, Q^T K_qq Q, Phi_P Q.
        assert_close_relative(b.modal_moment, a.modal_moment @ rot, EIG_RTOL, f"modal_moment ({label})")
        assert_close_relative(b.inertia_q, rot.T @ a.inertia_q, EIG_RTOL, f"inertia_q ({label})")
        assert_close_relative(b.modal_mass, np.eye(case.n_modes), EIG_RTOL, f"modal_mass ({label})")
        assert_close_relative(b.coupling_0, rot.T @ a.coupling_0, EIG_RTOL, f"coupling_0 ({label})")
        assert_close_relative(b.coupling, rot.T @ a.coupling @ rot, EIG_RTOL, f"coupling ({label})")
        assert_close_relative(b.marker_modes, a.marker_modes @ rot, EIG_RTOL, f"marker_modes ({label})")
        # Invariants: trace, spectrum and frequencies of K_qq, the projector.
        np.testing.assert_allclose(jnp.trace(b.modal_stiffness), jnp.trace(a.modal_stiffness), rtol=EIG_RTOL)
        # K_qq = Phi^T K Phi carries the eigen-solution's absolute error, `accuracy` (see EIG_EPS), and so
        # do its eigenvalues: relative to the lowest, ~1e-10 (a relative 1e-10 bound failed here). A
        # frequency f = sqrt(lam) / 2 pi then to accuracy / (2 lam) relative, the two sides to twice that.
        lam_b = np.asarray(jnp.linalg.eigvalsh(b.modal_stiffness))
        np.testing.assert_allclose(lam_b, basis.eigenvalues, rtol=0, atol=2 * accuracy,
                                   err_msg=f"spectrum of K_qq ({label})")
        np.testing.assert_allclose(np.sqrt(lam_b) / (2 * np.pi), case.frequencies(x), rtol=accuracy / lam_b[0],
                                   err_msg=f"frequencies ({label})")
        assert_close_relative((phi @ rot) @ (phi @ rot).T @ m, phi @ phi.T @ m, EIG_RTOL, f"projector ({label})")
        # Motion: with q -> Q^T q, energies, marker positions and forces are the same.
        rng = np.random.default_rng(8)
        y = jnp.asarray(np.concatenate([rng.normal(size=3), 0.05 * rng.normal(size=case.n_modes)]))
        z = jnp.asarray(rng.normal(size=3 + case.n_modes))
        big = jax.scipy.linalg.block_diag(jnp.eye(3), rot)
        np.testing.assert_allclose(body_kinetic_energy(b, big.T @ y, big.T @ z), body_kinetic_energy(a, y, z),
                                   rtol=EIG_RTOL, err_msg=f"kinetic energy ({label})")
        assert_close_relative(body_inertia_and_elastic_forces(b, big.T @ y, big.T @ z),
                              big.T @ body_inertia_and_elastic_forces(a, y, z), EIG_RTOL,
                              f"quadratic-velocity and elastic forces ({label})")
        for marker in (0, 1):
            assert_close_relative(marker_position(b, marker, big.T @ y), marker_position(a, marker, y), EIG_RTOL,
                                  f"marker {marker} position ({label})")


# --- geometric stiffness of a spinning rod ------------------------------------------------------------


def test_geometric_stiffness_of_a_spinning_rod_matches_beam_theory():
    """`K_geo` of the first (bending) mode per unit `Omega^2`, against the Euler–Bernoulli value.

    A uniform beam spinning about its end A, free to stretch at B, carries the tension
    `N(x) = rho A Omega^2 (L^2 - x^2) / 2`; its first hinged–hinged mode, mass-normalised, is
    `phi = sqrt(2 / (rho A L)) sin(pi x / L)`, so `K_geo_11 = int N phi'^2 dx / Omega^2 = pi^2/3 - 1/4`
    whatever `rho`, `A`, `L`. The plane-stress FE rod (40 x 2 Q4, h / L = 0.06) differs by its
    shear and thickness effects, O((h / L)^2) = 0.4 %, and by the mode shape of the coarse mesh
    (the bilinear gradients of a sine on 40 elements: O((pi / 40)^2) = 0.6 %); 1 % covers both
    (measured 0.19 %, and 0.38 % / 0.14 % on 20 / 80 elements). The design is uniform and solid,
    like the beam (the rod's end columns are solid whatever the design). The matrix is symmetric
    to round-off, and design gradients flow through it (finite).
    """
    body = ffr_jax.cases.rod_body(40, 2, 2, modal_solver=fd.DenseModes())
    x = body.initial_design(1.0)
    k_geo = eqx.filter_jit(lambda body, x: body.geometric_stiffness(x))(body, x)
    assert_close_relative(k_geo, k_geo.T, 1e-12, "K_geo symmetry")
    np.testing.assert_allclose(k_geo[0, 0], np.pi**2 / 3 - 0.25, rtol=1e-2, err_msg="K_geo_11 vs beam theory")
    grad = eqx.filter_jit(lambda body, x: jax.grad(lambda x: body.geometric_stiffness(x)[0, 0])(x))(body, x)
    assert grad.shape == (body.n_design,) and np.all(np.isfinite(np.asarray(grad)))
