"""The modal solver interface."""

import abc

import equinox as eqx
import jax.numpy as jnp

from ..assembly import FEModel
from .interface import ReductionLayout


class AbstractModalSolver(eqx.Module):
    """Computes the eigenmodes and static modes of a [`ReductionLayout`][] for one design.

    Implementations: [`DenseModes`][] (dense matrices, LAPACK, forward and reverse mode),
    [`LanczosModes`][] (sparse, shift-invert Lanczos on the host, reverse mode), and
    [`AutoModes`][] (picks one by the size of the mesh).
    """

    @abc.abstractmethod
    def solve(self, model: FEModel, youngs, densities, layout: ReductionLayout, n_modes: int):
        """The `n_modes` lowest eigenpairs with `layout.removed` held and the static modes.

        **Arguments:**
        - `model`: the [`FEModel`][]; `youngs`, `densities`: `(n_elements,)` element values.
        - `layout`: held, interface and interior degrees of freedom (static).
        - `n_modes`: number of eigenmodes (static).

        **Returns:** `(eigenvalues, modes)`: `(n_modes,)` ascending and
        `(n_dof, n_modes + n_static)` (see [`ModalBasis`][]).
        """


def check_modes(eigenvalues, modes, what: str):
    """Raise at run time (`eqx.error_if`) on non-finite modes or a non-positive eigenvalue."""
    return eqx.error_if(
        eigenvalues,
        ~jnp.all(jnp.isfinite(modes)) | ~jnp.all(jnp.isfinite(eigenvalues)) | (eigenvalues[0] <= 0.0),
        f"{what} failed (non-finite modes, a solver that did not converge, or a zero/negative eigenvalue): "
        "the reference conditions do not remove the rigid-body motions, or the design makes K or M singular.",
    )


def check_size(layout: ReductionLayout, n_modes: int, margin: int, what: str) -> None:
    if not isinstance(n_modes, int) or not 0 < n_modes < layout.n_interior - margin:
        raise ValueError(
            f"n_modes={n_modes} must be a positive int smaller than the number of interior degrees of freedom "
            f"({layout.n_interior}) minus {margin} for {what}; the derivative of the retained subspace needs "
            "discarded modes."
        )
