"""Modal truncation with a derivative that is stable for close or equal retained eigenvalues."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


class ModalBasis(eqx.Module):
    """Retained modes of `K phi = omega^2 M phi`, mass-normalised (`Phi^T M Phi = I`).

    - `eigenvalues`: `(n_modes,)` the retained `omega^2`, ascending.
    - `modes`: `(n_dof, n_modes)` the shape vectors on all degrees of freedom (zero on the
      constrained ones).
    """

    eigenvalues: Float[Array, " n_modes"]
    modes: Float[Array, "n_dof n_modes"]

    @property
    def frequencies(self) -> Float[Array, " n_modes"]:
        """Natural frequencies in Hz, `omega / (2 pi)`."""
        return jnp.sqrt(jnp.maximum(self.eigenvalues, 0.0)) / (2 * jnp.pi)


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
    symmetric (`dPhi = Phi C + Phi_d E` with `C = -1/2 Phi^T dM Phi`), not that of individual
    eigenvectors. Any quantity invariant under `Phi -> Phi Q` (`Q` orthogonal), such as the
    M-orthogonal projector, `Phi^T K Phi` up to rotation, or the objective of a multibody
    simulation, therefore gets its exact derivative, and the only eigenvalue gaps divided by are
    those between retained (`i`) and discarded (`j`) modes:

    `E_ji = phi_j^T (dK - lam_i dM) phi_i / (lam_i - lam_j)`  (Nelson 1976; the modal form).

    The eigenvalue derivatives `dlam_i = phi_i^T (dK - lam_i dM) phi_i` are exact for simple
    eigenvalues; equal retained eigenvalues have no derivative individually (their sum does).

    **Arguments:**
    - `k`, `m`: `(n, n)` symmetric stiffness and positive definite mass (free degrees of freedom).
    - `n_modes`: how many modes to keep (static).

    **Returns:** `(lam, Phi)`, shapes `(n_modes,)` and `(n, n_modes)`.
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


def hinged_modes(k: Float[Array, "n_dof n_dof"], m: Float[Array, "n_dof n_dof"], fixed_dofs: tuple[int, ...],
                 n_modes: int) -> ModalBasis:
    """Normal modes with the degrees of freedom `fixed_dofs` held at zero (REFERENCE_CASE §2).

    Solves `K_ff phi = omega^2 M_ff phi` on the free degrees of freedom, keeps the `n_modes`
    lowest, mass-normalised, and pads them with zeros on `fixed_dofs`.

    **Arguments:**
    - `k`, `m`: `(n_dof, n_dof)` global stiffness and consistent mass.
    - `fixed_dofs`: static tuple of constrained degrees of freedom (for the rod: `u_x(A)`,
      `u_y(A)`, `u_y(B)`).
    - `n_modes`: number of retained modes (static).

    **Returns:** a [`ModalBasis`][].
    """
    n_dof = k.shape[0]
    free = np.setdiff1d(np.arange(n_dof), np.asarray(fixed_dofs, dtype=int))
    if not 0 < n_modes < free.size:
        raise ValueError(
            f"n_modes={n_modes} must be positive and smaller than the number of free degrees of freedom "
            f"({free.size}); the derivative of the retained subspace needs at least one discarded mode."
        )
    k_ff = k[np.ix_(free, free)]
    m_ff = m[np.ix_(free, free)]
    lam, phi_f = retained_eigenpairs(k_ff, m_ff, n_modes)
    lam = eqx.error_if(
        lam,
        ~jnp.all(jnp.isfinite(phi_f)) | (lam[0] <= 0.0),
        "Modal analysis failed (non-finite modes or a zero/negative eigenvalue): the constraints do "
        "not remove the rigid-body motions, or the design makes K or M singular.",
    )
    phi = jnp.zeros((n_dof, n_modes), dtype=phi_f.dtype).at[free].set(phi_f)
    return ModalBasis(eigenvalues=lam, modes=phi)
