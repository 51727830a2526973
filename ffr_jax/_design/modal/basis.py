"""The retained modal basis of a flexible body: eigenmodes, then static (interface) modes."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float


class ModalBasis(eqx.Module):
    """Shape vectors `Phi = [Phi_eig, Psi]` on all degrees of freedom of a body.

    - `eigenvalues`: `(n_modes,)` the retained `omega^2` of `K phi = omega^2 M phi` with the
      reference conditions and the interface degrees of freedom held, ascending.
    - `modes`: `(n_dof, n_modes + n_static)`: first the eigenmodes (mass-normalised, zero on the
      held degrees of freedom), then the static modes of the interfaces (Craig–Bampton
      constraint modes; neither normalised nor M-orthogonal to the eigenmodes).
    - `n_static`: number of static modes (static).

    Everything downstream (body data, the multibody model, objectives) depends only on the span
    of `modes`, so quantities are compared through projectors, frequencies and other invariants.
    """

    eigenvalues: Float[Array, " n_modes"]
    modes: Float[Array, "n_dof n_q"]
    n_static: int = eqx.field(static=True, default=0)

    @property
    def n_modes(self) -> int:
        """Number of eigenmodes."""
        return self.eigenvalues.shape[0]

    @property
    def eigenmodes(self) -> Float[Array, "n_dof n_modes"]:
        return self.modes[:, : self.n_modes]

    @property
    def static_modes(self) -> Float[Array, "n_dof n_static"]:
        return self.modes[:, self.n_modes :]

    @property
    def frequencies(self) -> Float[Array, " n_modes"]:
        """Natural frequencies of the eigenmodes in Hz, `omega / (2 pi)`."""
        return jnp.sqrt(jnp.maximum(self.eigenvalues, 0.0)) / (2 * jnp.pi)
