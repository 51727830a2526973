"""Dense modal solver: full generalized eigen-solution, subspace-stable derivative (forward and reverse)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..assembly import FEModel, dense_matrix
from ..solid_assembly import SolidFEModel
from ..solid_layout import SolidReductionLayout
from .base import AbstractModalSolver, check_modes, check_size, stiffness_scale
from .interface import ReductionLayout


def _full_generalized_eigh(k, m):
    """All eigenpairs of `k v = lam m v`, `v^T m v = I`, via a Cholesky transformation."""
    chol = jnp.linalg.cholesky(m)
    a = jax.scipy.linalg.solve_triangular(chol, k, lower=True)
    a = jax.scipy.linalg.solve_triangular(chol, a.T, lower=True)
    a = 0.5 * (a + a.T)
    lam, w = jnp.linalg.eigh(a)
    v = jax.scipy.linalg.solve_triangular(chol.T, w, lower=False)
    return lam, v


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def retained_eigenpairs(k: Float[Array, "n n"], m: Float[Array, "n n"], n_modes: int):
    """The `n_modes` lowest eigenpairs of `k phi = lam m phi`, `Phi^T m Phi = I`.

    The derivative is that of the retained *subspace* in the gauge where `Phi^T M dPhi` is
    symmetric: `dPhi = Phi C + Phi_d E` with `C = -1/2 Phi^T dM Phi` and, over the discarded
    modes `j` and retained modes `i`,

    `E_ji = phi_j^T (dK - lam_i dM) phi_i / (lam_i - lam_j)`  (Nelson 1976, modal form).

    Only gaps between retained and discarded eigenvalues are divided by, so any quantity
    invariant under `Phi -> Phi Q` gets its exact derivative even where retained eigenvalues
    coincide or cross. `dlam_i = phi_i^T (dK - lam_i dM) phi_i` is exact for simple eigenvalues.

    **Arguments:** `k`, `m` `(n, n)` symmetric stiffness and positive definite mass;
    `n_modes` (static).

    **Returns:** `(lam, Phi)`, `(n_modes,)` and `(n, n_modes)`.

    !!! cite "Reference"
        R. B. Nelson, "Simplified calculation of eigenvector derivatives", AIAA J. 14 (1976)
        1201–1205.
    """
    lam, v = _full_generalized_eigh(k, m)
    return lam[:n_modes], v[:, :n_modes]


@retained_eigenpairs.defjvp
def _retained_eigenpairs_jvp(n_modes, primals, tangents):
    k, m = primals
    dk, dm = tangents
    lam_all, v_all = _full_generalized_eigh(k, m)
    lam, phi = lam_all[:n_modes], v_all[:, :n_modes]
    lam_d, phi_d = lam_all[n_modes:], v_all[:, n_modes:]
    dk_phi = dk @ phi
    dm_phi = dm @ phi
    dlam = jnp.einsum("ni,ni->i", phi, dk_phi) - lam * jnp.einsum("ni,ni->i", phi, dm_phi)
    inside = -0.5 * phi.T @ dm_phi
    gap = lam[None, :] - lam_d[:, None]
    outside = (phi_d.T @ dk_phi - (phi_d.T @ dm_phi) * lam[None, :]) / gap
    dphi = phi @ inside + phi_d @ outside
    return (lam, phi), (dlam, dphi)


class DenseModes(AbstractModalSolver):
    """Dense `K`, `M` and a full eigen-solution of the interior problem (small meshes).

    Eigenmodes by `retained_eigenpairs` on `(K_II, M_II)`; static modes
    `Psi_I = -K_II^-1 K_IB U_B` by a dense solve. Differentiable in forward and reverse mode;
    cost cubic in the number of degrees of freedom (use [`LanczosModes`][] beyond a few thousand).
    """

    def solve(self, model: FEModel | SolidFEModel, youngs, densities, layout: ReductionLayout | SolidReductionLayout,
              n_modes: int):
        check_size(layout, n_modes, 0, "DenseModes")
        if layout.n_rigid:
            raise ValueError("DenseModes needs reference conditions that remove the rigid-body motions; the modes of a "
                             "free solid part are free_modes_dense (dense) or LanczosModes (sparse).")
        k = dense_matrix(model, youngs, "stiffness")
        m = dense_matrix(model, densities, "mass")
        interior = layout.interior
        ii = np.ix_(interior, interior)
        lam, phi_i = retained_eigenpairs(k[ii], m[ii], n_modes)
        modes = jnp.zeros((model.n_dof, n_modes), dtype=phi_i.dtype).at[interior].set(phi_i)
        if layout.n_static:
            boundary = np.asarray(layout.boundary)
            u_b = jnp.asarray(layout.patterns)
            x_i = -jnp.linalg.solve(k[ii], k[np.ix_(interior, boundary)] @ u_b)
            psi = jnp.zeros((model.n_dof, layout.n_static), dtype=x_i.dtype).at[interior].set(x_i).at[boundary].set(u_b)
            modes = jnp.concatenate([modes, psi], axis=1)
        lam, modes = check_modes(lam, modes, "Dense modal analysis", stiffness_scale(model, youngs, densities))
        return lam, modes
