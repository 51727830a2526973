"""Modal reduction: eigen-solution, derivatives of the retained subspace, invariance under Phi -> Phi Q.

Modes are compared only through quantities invariant under sign flips and rotations inside the
retained subspace (frequencies, the M-orthogonal projector `P = Phi Phi^T M`, traces and
eigenvalues of `Phi^T K Phi`), never mode by mode.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from helpers import assert_close_relative, random_design, random_orthogonal, small_case

import ffr_jax
from ffr_jax._body_dynamics import body_inertia_and_elastic_forces, body_kinetic_energy, marker_position

# Finite differences against forward/reverse mode.
FD_RTOL = 1e-6
# Equalities that hold in exact arithmetic between quantities computed from the same eigen-solution
# (frequencies from eigenvalues, body data of Phi and of Phi Q): round-off of a few operations on
# well-scaled numbers, ~1e-15…1e-13 measured; far below this bound, and far above it for any error.
EIG_RTOL = 1e-10
# An eigen-solution itself is accurate only relative to the largest eigenvalue of the pencil: a
# backward-stable symmetric-definite solver (Cholesky reduction to C = L^-1 K L^-T, then a
# symmetric eigensolver: the library's and LAPACK's dsygvd alike) returns every eigenvalue to
# p(n) eps ||C||_2 = p(n) eps lambda_max in absolute terms, and eigenpairs with residuals
# |K phi - lam M phi| of the same size times |M phi| (Golub & Van Loan, Matrix Computations,
# 4th ed., §8.7 and §8.4). On the 12 x 2 rod lambda_max / lambda_1 = 3e6, so the lowest eigenvalue
# is known to ~1e-10 relative only: a relative tolerance of 1e-10 on it is a coin toss (issue 11).
# p(n) is taken as n (the textbook worst case); measured: 0.1–0.7 eps lambda_max.
EIG_EPS = np.finfo(float).eps


def _eigen_accuracy(case, x):
    """`(n eps lambda_max, lambda_max)` of the free hinged–hinged pencil at design `x` (see EIG_EPS)."""
    k, m = (np.asarray(a) for a in case.fe_matrices(x))
    free = np.setdiff1d(np.arange(case.mesh.n_dof), case.fixed_dofs)
    lam_max = scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)], eigvals_only=True)[-1]
    return free.size * EIG_EPS * lam_max, lam_max


def _unit_direction(n, seed):
    v = np.random.default_rng(seed).normal(size=n)
    return jnp.asarray(v / np.linalg.norm(v))


# --- the eigen-solution ---------------------------------------------------------------------------


def test_hinged_modes_solve_the_eigenproblem():
    case = small_case()
    x = random_design(case, 0)
    k, m = (np.asarray(a) for a in case.fe_matrices(x))
    basis = case.modes(x)
    phi, lam = np.asarray(basis.modes), np.asarray(basis.eigenvalues)
    free = np.setdiff1d(np.arange(case.mesh.n_dof), case.fixed_dofs)
    k_ff, m_ff = k[np.ix_(free, free)], m[np.ix_(free, free)]
    # Every eigenvalue of the free pencil by LAPACK's symmetric-definite solver (an independent
    # implementation of the same backward-stable algorithm), and the accuracy of either solver.
    lam_all = scipy.linalg.eigh(k_ff, m_ff, eigvals_only=True)
    accuracy = free.size * EIG_EPS * lam_all[-1]
    assert np.all(phi[list(case.fixed_dofs)] == 0.0), "modes vanish on the fixed dofs"
    assert np.all(np.diff(lam) > 0.0), "eigenvalues ascending"
    residual = np.abs((k @ phi)[free] - (m @ phi * lam)[free]).max(axis=0)
    assert np.all(residual <= accuracy * np.abs((m @ phi)[free]).max(axis=0)), (
        f"K Phi = M Phi Lambda on the free dofs: residuals {residual} against {accuracy:.2e} |M phi|")
    # Phi^T M Phi = I: the M-orthonormalisation by the Cholesky factor is accurate to n eps cond(M)
    # (cond(M) = 18 here; measured 1e-15).
    m_orthonormal = free.size * EIG_EPS * np.linalg.cond(m_ff)
    assert np.abs(phi.T @ m @ phi - np.eye(case.n_modes)).max() <= m_orthonormal, "Phi^T M Phi = I"
    assert np.abs(phi.T @ k @ phi - np.diag(lam)).max() <= accuracy, "Phi^T K Phi = diag(omega^2)"
    np.testing.assert_allclose(basis.frequencies, np.sqrt(lam) / (2 * np.pi), rtol=EIG_RTOL)
    # The retained modes are the lowest: the same eigenvalues as the lowest of the full free problem,
    # each solver's error being at most `accuracy` (absolute). The lowest discarded one is far above.
    np.testing.assert_allclose(lam, lam_all[: case.n_modes], rtol=0, atol=2 * accuracy,
                               err_msg="retained eigenvalues are the lowest ones")
    assert lam_all[case.n_modes] - lam[-1] > 1e3 * accuracy, "the first discarded eigenvalue is well apart"


# --- derivatives through the design pipeline ----------------------------------------------------

# The eigen-solver returns the low eigenvalues to an absolute accuracy of about eps * lambda_max, and
# lambda_max / lambda_1 is large for a stiff, light FE model: a central difference with a step of
# 1e-5 already shows round-off of ~1e-5 relative in the low frequencies. The five-point stencil
# with a step of 2e-3 keeps both truncation (h^4) and round-off (1 / h) below 1e-7 relative.
FD_STEP = 2e-3
INVARIANTS = ("frequency 1", "frequency 2", "frequency 3", "frequency 4", "trace(Phi^T K Phi)",
              "projector contraction", "body-data invariants")


def _five_point(f, x, v, step=FD_STEP):
    return (-f(x + 2 * step * v) + 8 * f(x + step * v) - 8 * f(x - step * v) + f(x - 2 * step * v)) / (12 * step)


def _design_invariants(case):
    """Span-invariant functionals of the design, stacked: the frequencies, trace(Phi^T K Phi), the
    M-orthogonal projector contracted with a fixed random matrix, and a sum of rotation invariants
    of all the body-data fields."""
    w = jnp.asarray(np.random.default_rng(42).normal(size=(case.mesh.n_dof, case.mesh.n_dof)))

    def invariants(x):
        k, m = case.fe_matrices(x)
        basis = ffr_jax.hinged_modes(k, m, case.fixed_dofs, case.n_modes)
        phi = basis.modes
        d = ffr_jax.flexible_body_data(case.mesh, m, k, phi, case.marker_nodes)
        body = (d.mass + d.inertia + jnp.sum(d.modal_moment**2) + d.inertia_q @ d.inertia_q
                + d.coupling_0 @ d.coupling_0 + jnp.sum(d.coupling**2) + jnp.sum(d.marker_modes**2)
                + jnp.trace(d.modal_mass) + 1e-6 * jnp.sum(d.modal_stiffness**2))
        projector = jnp.sum(w * (phi @ (phi.T @ m)))
        return jnp.concatenate([basis.frequencies, jnp.stack([jnp.trace(d.modal_stiffness), projector, body])])

    return jax.jit(invariants)


@pytest.fixture(scope="module")
def invariants():
    return _design_invariants(small_case())


def _assert_each(actual, expected, rtol, what):
    for name, a, e in zip(INVARIANTS, np.asarray(actual), np.asarray(expected)):
        np.testing.assert_allclose(a, e, rtol=rtol, err_msg=f"{what}: {name}")


def test_frequencies_are_the_case_frequencies(invariants):
    """The compiled pipeline and `case.frequencies` solve the same eigenproblem (differently compiled):
    each eigenvalue to `accuracy` absolute, so a frequency `f = sqrt(lam) / 2 pi` to `accuracy / (2 lam)`
    relative, and the two to twice that."""
    case = small_case()
    x = random_design(case, 0)
    accuracy, _ = _eigen_accuracy(case, x)
    expected = np.asarray(case.frequencies(x))
    # (a scalar bound: that of the lowest frequency, the least accurate one)
    np.testing.assert_allclose(invariants(x)[: case.n_modes], expected, rtol=accuracy / (2 * np.pi * expected[0]) ** 2)


@pytest.mark.parametrize("seed", [0, 1])
def test_jvp_matches_finite_differences(invariants, seed):
    case = small_case()
    x = random_design(case, seed)
    v = _unit_direction(case.n_design, seed + 100)
    _, tangent = jax.jvp(invariants, (x,), (v,))
    _assert_each(tangent, _five_point(invariants, x, v), FD_RTOL, f"JVP against FD (seed {seed})")


def test_vjp_matches_finite_differences_and_jvp(invariants):
    """`<u, J v>` from the VJP equals the finite difference and the JVP (dot-product test), and the
    gradient of trace(Phi^T K Phi) matches differences along single design variables."""
    case = small_case()
    x = random_design(case, 2)
    v = _unit_direction(case.n_design, 200)
    y, pullback = jax.vjp(invariants, x)
    _, tangent = jax.jvp(invariants, (x,), (v,))
    # Reverse and forward mode evaluate the same linear map in another order: they differ by
    # round-off in sums such as phi^T dK phi, whose terms reach lambda_max while the derivative of
    # the lowest eigenvalue is of size lambda_1 (a ratio of 3e6 here): eps lambda_max / lambda_1
    # relative, times a small constant (10); measured 1e-12 for frequency 1, 1e-15 for the others.
    accuracy, lam_max = _eigen_accuracy(case, x)
    vjp_vs_jvp = 10 * EIG_EPS * lam_max / float(case.modes(x).eigenvalues[0])
    fd = _five_point(invariants, x, v)
    for i, name in enumerate(INVARIANTS):
        (row,) = pullback(jnp.zeros_like(y).at[i].set(1.0))
        assert np.all(np.isfinite(row)), f"gradient of {name} is finite"
        np.testing.assert_allclose(row @ v, fd[i], rtol=FD_RTOL, err_msg=f"VJP against FD: {name}")
        np.testing.assert_allclose(row @ v, tangent[i], rtol=vjp_vs_jvp, err_msg=f"VJP against JVP: {name}")
    (grad_trace,) = pullback(jnp.zeros_like(y).at[4].set(1.0))
    for e in (0, case.n_design // 2, case.n_design - 1):
        unit = jnp.zeros(case.n_design).at[e].set(1.0)
        np.testing.assert_allclose(grad_trace[e], _five_point(invariants, x, unit)[4], rtol=FD_RTOL,
                                   err_msg=f"d trace(Phi^T K Phi) / dx_{e}")


def test_subspace_derivative_gauge():
    """The documented gauge: `Phi^T M dPhi` is symmetric, hence `= -1/2 Phi^T dM Phi`."""
    case = small_case()
    x = random_design(case, 5)
    v = _unit_direction(case.n_design, 500)
    (k, m), (dk, dm) = jax.jvp(case.fe_matrices, (x,), (v,))
    n_free = np.setdiff1d(np.arange(case.mesh.n_dof), case.fixed_dofs)
    ix = np.ix_(n_free, n_free)
    (_, phi), (_, dphi) = jax.jvp(lambda a, b: ffr_jax.retained_eigenpairs(a, b, case.n_modes), (k[ix], m[ix]),
                                  (dk[ix], dm[ix]))
    gauge = phi.T @ m[ix] @ dphi
    assert_close_relative(gauge, -0.5 * phi.T @ dm[ix] @ phi, EIG_RTOL, "Phi^T M dPhi = -1/2 Phi^T dM Phi")


# --- coincident and nearly coincident retained eigenvalues --------------------------------------


def _pencil_with_spectrum(eigenvalues, seed):
    """`(K, M)` with prescribed generalized eigenvalues: `M` random SPD, `V = L^-T Q` so that
    `V^T M V = I`, and `K = M V diag(lambda) V^T M`."""
    n = len(eigenvalues)
    rng = np.random.default_rng(seed)
    b = rng.normal(size=(n, n))
    m = b @ b.T + n * np.eye(n)
    chol = np.linalg.cholesky(m)
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    v = np.linalg.solve(chol.T, q)
    k = m @ v @ np.diag(eigenvalues) @ v.T @ m
    return jnp.asarray(0.5 * (k + k.T)), jnp.asarray(m)


def _symmetric(n, seed):
    a = np.random.default_rng(seed).normal(size=(n, n))
    return jnp.asarray(0.5 * (a + a.T))


SPECTRA = {
    "coincident": [1.0, 2.0, 3.0, 3.0, 5.0, 6.0, 7.0, 8.0],
    "1e-8 apart": [1.0, 2.0, 3.0, 3.0 + 1e-8, 5.0, 6.0, 7.0, 8.0],
    "coincident triple": [0.5, 3.0, 3.0, 3.0, 4.0, 6.0, 6.0, 9.0],
}


@pytest.mark.parametrize("spectrum", list(SPECTRA), ids=list(SPECTRA))
def test_span_invariants_differentiable_at_coincident_eigenvalues(spectrum):
    eigenvalues = SPECTRA[spectrum]
    n, n_modes = len(eigenvalues), 4
    k, m = _pencil_with_spectrum(eigenvalues, 0)
    dk, dm = _symmetric(n, 1), 0.1 * _symmetric(n, 2)
    w = jnp.asarray(np.random.default_rng(3).normal(size=(n, n)))

    @jax.jit
    def along_path(t):
        kt, mt = k + t * dk, m + t * dm
        lam, phi = ffr_jax.retained_eigenpairs(kt, mt, n_modes)
        return jnp.stack([jnp.sum(lam), jnp.trace(phi.T @ kt @ phi), jnp.sum(w * (phi @ phi.T @ mt))])

    lam, _ = ffr_jax.retained_eigenpairs(k, m, n_modes)
    np.testing.assert_allclose(lam, eigenvalues[:n_modes], rtol=EIG_RTOL, err_msg="constructed spectrum")
    t0 = jnp.array(0.0)
    _, forward = jax.jvp(along_path, (t0,), (jnp.array(1.0),))
    reverse = jax.jacrev(along_path)(t0)
    fd = _five_point(along_path, t0, jnp.array(1.0), step=1e-4)
    assert np.all(np.isfinite(forward)) and np.all(np.isfinite(reverse)), "finite derivative"
    names = "sum of retained eigenvalues, trace(Phi^T K Phi), projector contraction"
    np.testing.assert_allclose(forward, fd, rtol=FD_RTOL, err_msg=f"JVP of {names}")
    np.testing.assert_allclose(reverse, forward, rtol=1e-12, err_msg=f"reverse vs forward mode of {names}")


# --- invariance under Phi -> Phi Q ----------------------------------------------------------------


def test_rotating_the_retained_basis_changes_no_invariant():
    case = small_case()
    x = random_design(case, 6)
    k, m = case.fe_matrices(x)
    basis = case.modes(x)
    phi = basis.modes
    q = jnp.asarray(random_orthogonal(case.n_modes, 7))
    accuracy, _ = _eigen_accuracy(case, x)
    flips = jnp.diag(jnp.array([1.0, -1.0, -1.0, 1.0]))
    for label, rot in (("sign flips", flips), ("orthogonal Q", q)):
        a = ffr_jax.flexible_body_data(case.mesh, m, k, phi, case.marker_nodes)
        b = ffr_jax.flexible_body_data(case.mesh, m, k, phi @ rot, case.marker_nodes)
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
        # K_qq = Phi^T K Phi carries the eigen-solution's absolute error, `accuracy` (test above), and
        # so do its eigenvalues: relative to the lowest, ~1e-10 (a relative 1e-10 bound failed here).
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
