"""Free-free modal analysis of a solid part: the six rigid-body modes removed.

A free solid has six rigid-body modes, `K R = 0` for every design, with `R` `(n_dof, 6)` the
three translations and three rotations of the mesh's nodes. The elastic modes are the lowest
eigenpairs of `K phi = lam M phi` on the M-orthogonal complement of `R`. Two solvers:

- [`free_modes_dense`][]: JAX, differentiable (forward and reverse mode) through the planar
  chain's `retained_eigenpairs` (the subspace-stable derivative), on the deflated pencil
  `K_s = K + sigma (M R)(R^T M R)^-1 (M R)^T`, which leaves the elastic eigenpairs unchanged
  (`R^T M phi = 0`) and moves the rigid ones to `sigma` above the retained range, so that no gap
  between a retained and a discarded eigenvalue is small. Cubic cost: small parts.
- [`free_modes_sparse`][]: NumPy/SciPy on the host, shift-invert Lanczos below zero (`K - sigma M`
  is positive definite for `sigma < 0`), for large parts (10^5 elements); not differentiable.
"""

import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.sparse.linalg as spla

from .modal.dense import retained_eigenpairs
from .solid_assembly import SolidFEModel, solid_csc_matrices, solid_dense_matrix
from .solid_layout import rigid_motions as rigid_motions


def _stiffness_scale(model: SolidFEModel, youngs, densities):
    """`max_e E_e tr(K_e) / (rho_e tr(M_e))`, within a small factor of `lam_max` (see `modal.base.stiffness_scale`)."""
    trace_k = jnp.trace(model.unit_stiffness, axis1=1, axis2=2)
    trace_m = jnp.trace(model.unit_mass, axis1=1, axis2=2)
    return jnp.max(youngs * trace_k / (densities * trace_m))


def _check_n_modes(model: SolidFEModel, n_modes: int, margin: int) -> None:
    if not isinstance(n_modes, int) or isinstance(n_modes, bool) or not 0 < n_modes < model.n_dof - 6 - margin:
        raise ValueError(f"n_modes={n_modes} must be a positive int below the number of degrees of freedom less the "
                         f"six rigid-body modes and {margin} ({model.n_dof - 6 - margin} here).")


def free_modes_dense(model: SolidFEModel, youngs, densities, n_modes: int):
    """The `n_modes` lowest elastic eigenpairs of a free solid part, dense and differentiable.

    **Arguments:** `model`: the [`SolidFEModel`][]; `youngs`, `densities`: `(n_elements,)` element
    values (e.g. from [`SIMP`][]); `n_modes`: a Python int.

    **Returns:** `(lam, Phi)`: `(n_modes,)` ascending `omega^2` and `(n_dof, n_modes)` with
    `Phi^T M Phi = I` and `R^T M Phi = 0` (no rigid-body part).
    """
    _check_n_modes(model, n_modes, 0)
    k = solid_dense_matrix(model, youngs, "stiffness")
    m = solid_dense_matrix(model, densities, "mass")
    m_r = m @ jnp.asarray(rigid_motions(model.mesh.nodes))
    r_m_r = jnp.asarray(rigid_motions(model.mesh.nodes)).T @ m_r
    sigma = _stiffness_scale(model, youngs, densities)  # above every retained eigenvalue of a sane mesh
    k_s = k + sigma * m_r @ jnp.linalg.solve(r_m_r, m_r.T)
    return retained_eigenpairs(0.5 * (k_s + k_s.T), m, n_modes)


def free_modes_sparse(model: SolidFEModel, youngs, densities, n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """The `n_modes` lowest elastic eigenpairs of a free solid part on the host (sparse, large parts).

    Shift-invert Lanczos (ARPACK, SuperLU) with the shift `-1e-8 x` the stiffness scale for the
    `n_modes + 6` lowest eigenpairs, a Rayleigh–Ritz step on the converged subspace, and the six
    lowest dropped after checking that they are the rigid-body modes (eigenvalues below `1e-10` of
    the stiffness scale, and the seventh above it: else a detached piece or mechanism, a
    `ValueError`).

    **Arguments:** as [`free_modes_dense`][], NumPy or concrete JAX arrays.

    **Returns:** `(lam, Phi)` NumPy arrays, `(n_modes,)` and `(n_dof, n_modes)`, `Phi^T M Phi = I`.
    """
    _check_n_modes(model, n_modes, 1)
    youngs, densities = np.asarray(youngs, dtype=np.float64), np.asarray(densities, dtype=np.float64)
    k, m = solid_csc_matrices(model, youngs, densities)
    scale = float(_stiffness_scale(model, jnp.asarray(youngs), jnp.asarray(densities)))
    sigma = -1e-8 * scale
    # SuperLU with a symmetric ordering and no pivoting (K - sigma M is positive definite), as the planar
    # LanczosModes: SciPy's default (COLAMD, partial pivoting) fills a 3D factor several times more.
    lu = spla.splu((k - sigma * m).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    op = spla.LinearOperator(k.shape, matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(k.shape[0])
    _, basis = spla.eigsh(k, n_modes + 6, M=m, sigma=sigma, OPinv=op, which="LM", v0=v0, tol=0.0)
    k_r, m_r = basis.T @ (k @ basis), basis.T @ (m @ basis)
    lam, rot = scipy.linalg.eigh(0.5 * (k_r + k_r.T), 0.5 * (m_r + m_r.T))
    if not (np.all(np.abs(lam[:6]) < 1e-10 * scale) and lam[6] > 1e-10 * scale):
        raise ValueError(
            "free_modes_sparse: the part does not have exactly six rigid-body modes (eigenvalues "
            f"{lam[:7] / scale} of the stiffness scale): a detached piece, a piece hinged at a node or an edge, or "
            "elements so distorted that K is numerically singular. Check the mesh (connected through faces)."
        )
    return lam[6:], basis @ rot[:, 6:]
