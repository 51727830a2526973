"""Sparse modal truncation: shift-invert Lanczos for the retained modes, a VJP from sparse solves.

The sparse counterpart of [`hinged_modes`][]. The forward solve runs on the host through
`jax.pure_callback`: `K_ff` and `M_ff` are assembled as SciPy CSC matrices, `K_ff` is factorised
once (SuperLU, minimum-degree ordering; `K_ff` is positive definite once the hinges remove the
rigid-body motions) and ARPACK's shift-invert Lanczos (`eigsh`, shift 0) finds the `n_q` lowest
eigenpairs of `K phi = lam M phi`. A Rayleigh–Ritz step on the converged subspace makes `Phi`
exactly M-orthonormal and `Phi^T K Phi` diagonal. Memory and time grow about linearly with the
number of elements (the factor of a 2-D mesh has `O(n log n)` entries).

The derivative is the same subspace-stable one as the dense path's (see
[`retained_eigenpairs`][]): `dPhi = Phi C + W` with `C = -1/2 Phi^T dM Phi` and `W` the
component outside the retained subspace,

`(K - lam_i M) w_i = -(I - M Phi Phi^T) (dK - lam_i dM) phi_i`,  `Phi^T M w_i = 0`,

which equals the dense path's sum over all discarded modes `j`, `phi_j E_ji`, without computing
them. Only gaps between retained and discarded eigenvalues enter. In reverse mode the
cotangents `(lam_bar, Phi_bar)` need the transposed solves

`(K - lam_i M) z_i = -(I - M Phi Phi^T) phi_bar_i`,  `Phi^T M z_i = 0`,

after which the element cotangents are element-level quadratic forms (paper notation: the
gradient pulled back to `E_e` and `rho_e`):

`E_bar_e = sum_i (lam_bar_i phi_i^T K_e phi_i + z_i^T K_e phi_i)`,
`rho_bar_e = -sum_i lam_i (lam_bar_i phi_i^T M_e phi_i + z_i^T M_e phi_i) - 1/2 sum_ij G_ij phi_i^T M_e phi_j`,

with `G = Phi^T Phi_bar` and the element matrices `K_e`, `M_e` on element `e`'s degrees of
freedom. On the complement of the retained subspace `K - lam_i M` is positive definite, so the
solves are preconditioned conjugate gradients with the factor of `K` as preconditioner (condition
number `lam_{n+1} / (lam_{n+1} - lam_i)`: a few tens of iterations), all `n_q` columns at once.

References: Nelson, *Simplified calculation of eigenvector derivatives*, AIAA J. 14 (1976);
Lehoucq, Sorensen and Yang, *ARPACK Users' Guide* (1998), shift-invert mode.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.sparse.linalg as spla

from ._modes import ModalBasis
from ._sparse_fe import ElementOperator, _mesh_key, element_dofs, free_pattern, scipy_matrices
from ._fe import RodMesh


# Relative residual of the complement solves, and their iteration budget.
_SOLVE_RTOL = 1e-12
_SOLVE_MAXITER = 1000


def _factorise(k_ff):
    """SuperLU factor of the positive definite `K_ff` (symmetric mode, no pivoting)."""
    return spla.splu(k_ff, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def _host_eigenpairs(key, fixed_dofs, n_modes, youngs, densities):
    """Host: the `n_modes` lowest eigenpairs of `K_ff phi = lam M_ff phi` (NaN on failure)."""
    mesh = RodMesh(*key)
    k, m = scipy_matrices(mesh, np.asarray(youngs), np.asarray(densities), fixed_dofs)
    n = k.shape[0]
    failed = (np.full(n_modes, np.nan), np.full((n, n_modes), np.nan))
    try:
        lu = _factorise(k)
    except RuntimeError:  # exactly singular K_ff
        return failed
    op = spla.LinearOperator((n, n), matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n)
    ncv = min(n - 1, max(2 * n_modes + 1, 20))
    try:
        _, basis = spla.eigsh(k, n_modes, M=m, sigma=0.0, OPinv=op, v0=v0, ncv=ncv, tol=0.0)
    except (spla.ArpackNoConvergence, spla.ArpackError):
        return failed
    # Rayleigh–Ritz on the converged subspace: exact M-orthonormality and a diagonal Phi^T K Phi.
    k_r = basis.T @ (k @ basis)
    m_r = basis.T @ (m @ basis)
    lam, rot = scipy.linalg.eigh(0.5 * (k_r + k_r.T), 0.5 * (m_r + m_r.T))
    return lam.astype(float), (basis @ rot).astype(float)


def _host_complement_solve(key, fixed_dofs, youngs, densities, lam, phi, rhs):
    """Host: `z_i` with `(K - lam_i M) z_i = -(I - M Phi Phi^T) rhs_i`, `Phi^T M z_i = 0`, all columns.

    Preconditioned conjugate gradients on the M-orthogonal complement of `Phi`, where every
    `K - lam_i M` is positive definite; preconditioner `(I - Phi Phi^T M) K^-1`.
    Returns NaN columns if a column does not converge.
    """
    mesh = RodMesh(*key)
    k, m = scipy_matrices(mesh, np.asarray(youngs), np.asarray(densities), fixed_dofs)
    lam, phi, rhs = np.asarray(lam), np.asarray(phi), np.asarray(rhs)
    lu = _factorise(k)
    m_phi = m @ phi
    b = -(rhs - m_phi @ (phi.T @ rhs))

    def precondition(r):
        y = lu.solve(np.ascontiguousarray(r))
        return y - phi @ (m_phi.T @ y)

    z = np.zeros_like(b)
    r = b.copy()
    b_norm = np.linalg.norm(b, axis=0)
    y = precondition(r)
    p = y.copy()
    rho = np.sum(r * y, axis=0)
    converged = b_norm == 0.0
    for _ in range(_SOLVE_MAXITER):
        converged = converged | (np.linalg.norm(r, axis=0) <= _SOLVE_RTOL * b_norm)
        if np.all(converged):
            break
        q = k @ p - (m @ p) * lam
        alpha = np.where(converged, 0.0, rho / np.where(converged, 1.0, np.sum(p * q, axis=0)))
        z += alpha * p
        r -= alpha * q
        r -= m_phi @ (phi.T @ r)
        y = precondition(r)
        rho_new = np.sum(r * y, axis=0)
        beta = np.where(converged, 0.0, rho_new / np.where(converged, 1.0, rho))
        p = y + beta * p
        rho = rho_new
    z[:, ~converged] = np.nan
    return z


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1, 2))
def _sparse_retained_eigenpairs(key, fixed_dofs, n_modes, youngs, densities):
    n_free = free_pattern(RodMesh(*key), fixed_dofs).n
    shapes = (
        jax.ShapeDtypeStruct((n_modes,), youngs.dtype),
        jax.ShapeDtypeStruct((n_free, n_modes), youngs.dtype),
    )
    return jax.pure_callback(
        functools.partial(_host_eigenpairs, key, fixed_dofs, n_modes), shapes, youngs, densities,
        vmap_method="sequential",
    )


def _sparse_retained_eigenpairs_fwd(key, fixed_dofs, n_modes, youngs, densities):
    lam, phi = _sparse_retained_eigenpairs(key, fixed_dofs, n_modes, youngs, densities)
    return (lam, phi), (youngs, densities, lam, phi)


def _sparse_retained_eigenpairs_bwd(key, fixed_dofs, n_modes, residuals, cotangents):
    youngs, densities, lam, phi = residuals
    lam_bar, phi_bar = cotangents
    z = jax.pure_callback(
        functools.partial(_host_complement_solve, key, fixed_dofs),
        jax.ShapeDtypeStruct(phi.shape, phi.dtype), youngs, densities, lam, phi, phi_bar,
        vmap_method="sequential",
    )
    z = eqx.error_if(
        z, ~jnp.all(jnp.isfinite(z)),
        "Sparse eigen-derivative: the conjugate-gradient solve on the discarded subspace did not "
        "converge (the last retained and the first discarded eigenvalue are too close, or the "
        "design makes K singular). Retain one more mode, or use fe_path='dense' on small meshes.",
    )
    mesh = RodMesh(*key)
    free = free_pattern(mesh, fixed_dofs).free
    dofs = element_dofs(mesh)
    k_e, m_e = (jnp.asarray(a) for a in mesh.element_matrices())

    def on_elements(v):  # (n_free, n_q) -> (n_elements, 8, n_q), zero on fixed dofs
        return jnp.zeros((mesh.n_dof, v.shape[1]), v.dtype).at[free].set(v)[dofs]

    phi_e, z_e = on_elements(phi), on_elements(z)
    k_phi = jnp.einsum("ab,ebi->eai", k_e, phi_e)
    m_phi = jnp.einsum("ab,ebi->eai", m_e, phi_e)
    g = phi.T @ phi_bar
    g_sym = 0.5 * (g + g.T)
    youngs_bar = jnp.einsum("eai,eai,i->e", phi_e, k_phi, lam_bar) + jnp.einsum("eai,eai->e", z_e, k_phi)
    densities_bar = (
        -jnp.einsum("eai,eai,i->e", phi_e, m_phi, lam * lam_bar)
        - jnp.einsum("eai,eai,i->e", z_e, m_phi, lam)
        - 0.5 * jnp.einsum("eai,eaj,ij->e", phi_e, m_phi, g_sym)
    )
    return youngs_bar, densities_bar


_sparse_retained_eigenpairs.defvjp(_sparse_retained_eigenpairs_fwd, _sparse_retained_eigenpairs_bwd)


def sparse_hinged_modes(k: ElementOperator, m: ElementOperator, fixed_dofs: tuple[int, ...], n_modes: int) -> ModalBasis:
    """Normal modes with `fixed_dofs` held at zero, from matrix-free `K` and `M` (sparse path).

    Same result as [`hinged_modes`][] (`n_modes` lowest modes of `K_ff phi = omega^2 M_ff phi`,
    mass-normalised, zero on `fixed_dofs`), computed by shift-invert Lanczos on sparse matrices
    and differentiable in reverse mode (`jax.grad`, `jax.vjp`) with the subspace-stable
    derivative of the module docstring. Works under `jax.jit` and `jax.vmap` (designs are solved
    one after another on the host). Forward mode (`jax.jvp`) is not available on this path.

    **Arguments:**
    - `k`, `m`: [`ElementOperator`][]s of the stiffness and the mass on the same mesh.
    - `fixed_dofs`: static tuple of constrained degrees of freedom.
    - `n_modes`: number of retained modes (static).

    **Returns:** a [`ModalBasis`][].
    """
    if k.kind != "stiffness" or m.kind != "mass" or _mesh_key(k.mesh) != _mesh_key(m.mesh):
        raise ValueError("sparse_hinged_modes needs the stiffness and the mass ElementOperator of one mesh.")
    mesh = k.mesh
    fixed_dofs = tuple(int(d) for d in fixed_dofs)
    pattern = free_pattern(mesh, fixed_dofs)
    if not 0 < n_modes < pattern.n - 1:
        raise ValueError(
            f"n_modes={n_modes} must be positive and smaller than the number of free degrees of freedom "
            f"minus one ({pattern.n - 1}) for the sparse eigensolver; use fe_path='dense' on tiny meshes."
        )
    lam, phi_f = _sparse_retained_eigenpairs(_mesh_key(mesh), fixed_dofs, n_modes, k.values, m.values)
    lam = eqx.error_if(
        lam,
        ~jnp.all(jnp.isfinite(phi_f)) | ~jnp.all(jnp.isfinite(lam)) | (lam[0] <= 0.0),
        "Sparse modal analysis failed (K singular, Lanczos not converged, or a zero/negative eigenvalue): "
        "the constraints do not remove the rigid-body motions, or the design makes K or M singular.",
    )
    phi = jnp.zeros((mesh.n_dof, n_modes), dtype=phi_f.dtype).at[pattern.free].set(phi_f)
    return ModalBasis(eigenvalues=lam, modes=phi)
