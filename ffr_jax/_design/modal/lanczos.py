"""Sparse modal solver: shift-invert Lanczos on the host, reverse-mode derivative from sparse solves.

The forward solve runs on the host through `jax.pure_callback`: `K_II` and `M_II` (the interior
degrees of freedom: reference conditions and interfaces held) are assembled as SciPy CSC
matrices, `K_II` is factorised once (SuperLU, minimum-degree ordering, symmetric mode; it is
positive definite once the reference conditions remove the rigid-body motions), ARPACK's
shift-invert Lanczos (`eigsh`, shift 0) finds the `n_modes` lowest eigenpairs, a Rayleigh–Ritz
step on the converged subspace makes them exactly M-orthonormal with a diagonal `Phi^T K Phi`,
and the same factor gives the static modes `Psi_I = -K_II^-1 K_IB U_B`. Memory and time grow
about linearly with the number of elements.

**Derivative.** The eigenmodes get the subspace-stable derivative of [`retained_eigenpairs`][]:
`dPhi = Phi C + W`, `C = -1/2 Phi^T dM Phi`, with `W` outside the retained subspace,

`(K - lam_i M) w_i = -(I - M Phi Phi^T) (dK - lam_i dM) phi_i`,  `Phi^T M w_i = 0`,

which equals the sum over all discarded modes without computing them; only gaps between
retained and discarded eigenvalues enter. In reverse mode the cotangents
`(lam_bar, Phi_bar, Psi_bar)` need the transposed solves

`(K - lam_i M) z_i = -(I - M Phi Phi^T) phi_bar_i`,  `Phi^T M z_i = 0`   (eigenmodes),
`K_II w_s = psi_bar_s`                                                   (static modes),

after which the cotangents of the element values are element-level quadratic forms with the
unit element matrices `K_e`, `M_e`:

`E_bar_e = sum_i (lam_bar_i phi_i^T K_e phi_i + z_i^T K_e phi_i) - sum_s w_s^T K_e psi_s`,
`rho_bar_e = -sum_i lam_i (lam_bar_i phi_i^T M_e phi_i + z_i^T M_e phi_i) - 1/2 sum_ij G_ij phi_i^T M_e phi_j`,

with `G = sym(Phi^T Phi_bar)` (from `dPsi_I = -K_II^-1 (dK Psi)_I` for the static modes). On the
complement of the retained subspace `K - lam_i M` is positive definite, so the `z` solves are
preconditioned conjugate gradients with the factor of `K_II` as preconditioner (condition
number `lam_{n+1} / (lam_{n+1} - lam_i)`), all columns at once.

Every host array crosses the callback at full size `(n_dof, k)` (zero on held degrees of
freedom), so no index array of the mesh is ever a constant of the compiled program.

The same code serves planar and solid bodies: the element matrices are `(n_elements, d, d)` for
any element (`d = 8` for Q4, 24 for H8 and H11, 30 for Tet10), and the layout (a
`ReductionLayout`, or a supported solid part's `SolidReductionLayout`) assembles the host `K_II`,
`M_II`.

!!! cite "References"
    R. B. Nelson, "Simplified calculation of eigenvector derivatives", AIAA J. 14 (1976).

    R. B. Lehoucq, D. C. Sorensen, C. Yang, *ARPACK Users' Guide*, SIAM (1998), shift-invert mode.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.sparse.linalg as spla

from ..assembly import FEModel
from ..solid_assembly import SolidFEModel
from ..solid_layout import SolidReductionLayout
from .base import AbstractModalSolver, check_modes, check_size, stiffness_scale
from .interface import ReductionLayout


# Relative residual of the complement solves, and their iteration budget.
SOLVE_RTOL = 1e-12
SOLVE_MAXITER = 1000
# A free body (rigid-body modes left by the layout): the shift below zero, as a fraction of the stiffness scale, that
# makes `K - sigma M` positive definite, and the bound below which an eigenvalue counts as a rigid-body one.
RIGID_SHIFT = 1e-8
RIGID_BOUND = 1e-10


def _factorise(k):
    """SuperLU factor of the positive definite `K_II` (symmetric mode, no pivoting)."""
    return spla.splu(k, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def _boundary_load(layout: ReductionLayout | SolidReductionLayout, youngs, unit_k) -> np.ndarray:
    """`K U` for the interface patterns `U` (zero off the interfaces), `(n_dof, n_static)`, on the host."""
    mesh = layout.mesh
    u = np.zeros((mesh.n_dof, layout.n_static))
    u[list(layout.boundary)] = layout.patterns
    elements = layout.touching
    dofs = mesh.element_dofs()[elements]
    local = np.einsum("e,eab,ebk->eak", youngs[elements], unit_k[elements], u[dofs])
    out = np.zeros_like(u)
    np.add.at(out, dofs.ravel(), local.reshape(-1, layout.n_static))
    return out


def _host_scale(youngs, densities, unit_k, unit_m) -> float:
    """`stiffness_scale` on the host: `max_e E_e tr(K_e) / (rho_e tr(M_e))`."""
    return float(np.max(youngs * np.trace(unit_k, axis1=1, axis2=2) / (densities * np.trace(unit_m, axis1=1, axis2=2))))


def _shift(layout, youngs, densities, unit_k, unit_m) -> float:
    """The shift `sigma` of the factor `K_II - sigma M_II`: 0, or below zero for a layout with rigid-body modes."""
    return -RIGID_SHIFT * _host_scale(youngs, densities, unit_k, unit_m) if layout.n_rigid else 0.0


def _host_forward(layout: ReductionLayout | SolidReductionLayout, n_modes: int, youngs, densities, unit_k, unit_m):
    """Host: eigenpairs of `(K_II, M_II)` and static modes, full size; NaN on failure.

    With `layout.n_rigid = r > 0` (a free solid part) the `n_modes + r` lowest pairs are computed with the shift
    `sigma < 0` and the `r` lowest, which must be the rigid-body modes (below `RIGID_BOUND` of the stiffness scale,
    the next one above), are dropped; otherwise NaN."""
    youngs, densities, unit_k, unit_m = (np.asarray(a) for a in (youngs, densities, unit_k, unit_m))
    n_dof, interior = layout.mesh.n_dof, layout.interior
    lam_out = np.full(n_modes, np.nan)
    phi_out = np.zeros((n_dof, n_modes))
    psi_out = np.zeros((n_dof, layout.n_static))
    k, m = layout.csc_matrices(youngs, densities, unit_k, unit_m)
    n, n_rigid = k.shape[0], layout.n_rigid
    sigma = _shift(layout, youngs, densities, unit_k, unit_m)
    try:
        lu = _factorise((k - sigma * m).tocsc() if n_rigid else k)
    except RuntimeError:  # exactly singular K_II
        phi_out[:] = np.nan
        return lam_out, phi_out, psi_out
    op = spla.LinearOperator((n, n), matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n)
    ncv = min(n - 1, max(2 * (n_modes + n_rigid) + 1, 20))
    try:
        _, basis = spla.eigsh(k, n_modes + n_rigid, M=m, sigma=sigma, OPinv=op, v0=v0, ncv=ncv, tol=0.0)
    except (spla.ArpackNoConvergence, spla.ArpackError):
        phi_out[:] = np.nan
        return lam_out, phi_out, psi_out
    # Rayleigh–Ritz on the converged subspace: exact M-orthonormality and a diagonal Phi^T K Phi.
    k_r = basis.T @ (k @ basis)
    m_r = basis.T @ (m @ basis)
    lam, rot = scipy.linalg.eigh(0.5 * (k_r + k_r.T), 0.5 * (m_r + m_r.T))
    if n_rigid:
        bound = RIGID_BOUND * _host_scale(youngs, densities, unit_k, unit_m)
        if not (np.all(np.abs(lam[:n_rigid]) < bound) and lam[n_rigid] > bound):  # a mechanism or detached piece
            phi_out[:] = np.nan
            return lam_out, phi_out, psi_out
        lam, rot = lam[n_rigid:], rot[:, n_rigid:]
    phi_out[interior] = basis @ rot
    if layout.n_static:
        load = _boundary_load(layout, youngs, unit_k)
        psi_out[interior] = lu.solve(np.ascontiguousarray(-load[interior]))
        psi_out[list(layout.boundary)] = layout.patterns
    return lam.astype(float), phi_out, psi_out


def _complement_solve(k, m, lu, lam, phi, rhs):
    """`z_i` with `(K - lam_i M) z_i = -(I - M Phi Phi^T) rhs_i`, `Phi^T M z_i = 0`, all columns.

    Preconditioned conjugate gradients on the M-orthogonal complement of `Phi`, where every
    `K - lam_i M` is positive definite; preconditioner `(I - Phi Phi^T M) K^-1` (`lu` the factor of
    `K`, or of `K - sigma M`). `Phi` `(n, p)` may hold more columns than `lam` (`(k,)`, `k <= p`):
    the first `p - k` (a free body's rigid-body modes) are projected out and not solved for. NaN
    columns where a column does not converge.
    """
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
    for _ in range(SOLVE_MAXITER):
        converged = converged | (np.linalg.norm(r, axis=0) <= SOLVE_RTOL * b_norm)
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


def _host_backward(layout: ReductionLayout | SolidReductionLayout, youngs, densities, unit_k, unit_m, lam, phi,
                   phi_bar, psi_bar):
    """Host: the transposed solves `z` (eigenmodes) and `w` (static modes), and `v = R R^T phi_bar` (the
    M-orthonormal rigid-body modes `R` of a free body; zero otherwise), full size."""
    youngs, densities, unit_k, unit_m = (np.asarray(a) for a in (youngs, densities, unit_k, unit_m))
    interior = layout.interior
    k, m = layout.csc_matrices(youngs, densities, unit_k, unit_m)
    sigma = _shift(layout, youngs, densities, unit_k, unit_m)
    lu = _factorise((k - sigma * m).tocsc() if layout.n_rigid else k)
    phi_i, phi_bar_i = np.asarray(phi)[interior], np.asarray(phi_bar)[interior]
    v = np.zeros_like(np.asarray(phi_bar))
    held = phi_i
    if layout.n_rigid:
        rigid = layout.rigid[interior]
        chol = np.linalg.cholesky(rigid.T @ (m @ rigid))
        rigid = scipy.linalg.solve_triangular(chol, rigid.T, lower=True).T  # R^T M R = I
        held = np.concatenate([rigid, phi_i], axis=1)
        v[interior] = rigid @ (rigid.T @ phi_bar_i)
    z = np.zeros_like(np.asarray(phi_bar))
    z[interior] = _complement_solve(k, m, lu, np.asarray(lam), held, phi_bar_i)
    w = np.zeros_like(np.asarray(psi_bar))
    if layout.n_static:
        w[interior] = lu.solve(np.ascontiguousarray(np.asarray(psi_bar)[interior]))
    return z, w, v


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _lanczos_basis(layout, n_modes, youngs, densities, unit_k, unit_m, element_dofs):
    del element_dofs  # used by the derivative only
    n_dof = layout.mesh.n_dof
    shapes = (
        jax.ShapeDtypeStruct((n_modes,), youngs.dtype),
        jax.ShapeDtypeStruct((n_dof, n_modes), youngs.dtype),
        jax.ShapeDtypeStruct((n_dof, layout.n_static), youngs.dtype),
    )
    return jax.pure_callback(
        functools.partial(_host_forward, layout, n_modes), shapes, youngs, densities, unit_k, unit_m,
        vmap_method="sequential",
    )


def _lanczos_basis_fwd(layout, n_modes, youngs, densities, unit_k, unit_m, element_dofs):
    lam, phi, psi = _lanczos_basis(layout, n_modes, youngs, densities, unit_k, unit_m, element_dofs)
    return (lam, phi, psi), (youngs, densities, unit_k, unit_m, element_dofs, lam, phi, psi)


def _lanczos_basis_bwd(layout, n_modes, residuals, cotangents):
    youngs, densities, unit_k, unit_m, element_dofs, lam, phi, psi = residuals
    lam_bar, phi_bar, psi_bar = cotangents
    z, w, v = jax.pure_callback(
        functools.partial(_host_backward, layout),
        (jax.ShapeDtypeStruct(phi.shape, phi.dtype), jax.ShapeDtypeStruct(psi.shape, psi.dtype),
         jax.ShapeDtypeStruct(phi.shape, phi.dtype)),
        youngs, densities, unit_k, unit_m, lam, phi, phi_bar, psi_bar,
        vmap_method="sequential",
    )
    z = eqx.error_if(
        z, ~jnp.all(jnp.isfinite(z)),
        "Lanczos eigen-derivative: the conjugate-gradient solve on the discarded subspace did not converge "
        "(the last retained and the first discarded eigenvalue are too close, or the design makes K singular). "
        "Retain one more mode, or use DenseModes on small meshes.",
    )

    def on_elements(v):  # (n_dof, k) -> (n_elements, d, k), d the element's degrees of freedom
        return v[element_dofs]

    phi_e, z_e = on_elements(phi), on_elements(z)
    k_phi = jnp.einsum("eab,ebi->eai", unit_k, phi_e)
    m_phi = jnp.einsum("eab,ebi->eai", unit_m, phi_e)
    g = phi.T @ phi_bar
    g_sym = 0.5 * (g + g.T)
    youngs_bar = jnp.einsum("eai,eai,i->e", phi_e, k_phi, lam_bar) + jnp.einsum("eai,eai->e", z_e, k_phi)
    densities_bar = (
        -jnp.einsum("eai,eai,i->e", phi_e, m_phi, lam * lam_bar)
        - jnp.einsum("eai,eai,i->e", z_e, m_phi, lam)
        - 0.5 * jnp.einsum("eai,eaj,ij->e", phi_e, m_phi, g_sym)
    )
    if layout.n_rigid:  # the rigid-body part of dPhi: -R R^T dM Phi (K R = 0 for every design)
        densities_bar = densities_bar - jnp.einsum("eai,eai->e", on_elements(v), m_phi)
    if layout.n_static:
        psi_e, w_e = on_elements(psi), on_elements(w)
        youngs_bar = youngs_bar - jnp.einsum("eas,eab,ebs->e", w_e, unit_k, psi_e)
    return youngs_bar, densities_bar, None, None, None


_lanczos_basis.defvjp(_lanczos_basis_fwd, _lanczos_basis_bwd)


class LanczosModes(AbstractModalSolver):
    """Sparse shift-invert Lanczos (SciPy ARPACK + SuperLU on the host) with a reverse-mode derivative.

    Same result as [`DenseModes`][] (the lowest eigenpairs of the interior problem,
    mass-normalised, and the static modes), with memory and time about linear in the mesh size
    (planar bodies, and solid parts with supports: [`SolidDesignedBody`][]);
    the derivative of the module docstring. Works under `jax.jit` and `jax.vmap` (designs are
    solved one after another on the host); reverse mode only (`jax.grad`, `jax.vjp`): forward
    mode (`jax.jvp`) raises.
    """

    def solve(self, model: FEModel | SolidFEModel, youngs, densities, layout: ReductionLayout | SolidReductionLayout,
              n_modes: int):
        check_size(layout, n_modes, 1 + layout.n_rigid, "LanczosModes (ARPACK needs n_modes < n - 1; a free body's "
                   "rigid-body modes count too)")
        lam, phi, psi = _lanczos_basis(layout, n_modes, youngs, densities, model.unit_stiffness, model.unit_mass,
                                       model.element_dofs)
        modes = jnp.concatenate([phi, psi], axis=1) if layout.n_static else phi
        lam, modes = check_modes(lam, modes, "Lanczos modal analysis", stiffness_scale(model, youngs, densities))
        return lam, modes
