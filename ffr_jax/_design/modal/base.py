"""The modal solver interface."""

import abc

import equinox as eqx
import jax.numpy as jnp

from ..._errors import DesignError, error_if
from ..assembly import FEModel
from ..solid_assembly import SolidFEModel
from ..solid_layout import SolidReductionLayout
from .interface import ReductionLayout


class AbstractModalSolver(eqx.Module):
    """Computes the eigenmodes and static modes of a `ReductionLayout` for one design.

    Implementations: [`DenseModes`][] (dense matrices, LAPACK, forward and reverse mode),
    [`LanczosModes`][] (sparse, shift-invert Lanczos on the host, reverse mode), and
    [`AutoModes`][] (picks one by the size of the mesh).
    """

    @abc.abstractmethod
    def solve(self, model: FEModel | SolidFEModel, youngs, densities, layout: ReductionLayout | SolidReductionLayout,
              n_modes: int):
        """The `n_modes` lowest eigenpairs with `layout.removed` held and the static modes.

        **Arguments:**
        - `model`: the [`FEModel`][]; `youngs`, `densities`: `(n_elements,)` element values.
        - `layout`: held, interface and interior degrees of freedom (static).
        - `n_modes`: number of eigenmodes (static).

        **Returns:** `(eigenvalues, modes)`: `(n_modes,)` ascending and
        `(n_dof, n_modes + n_static)` (see [`ModalBasis`][]).
        """


# The lowest retained eigenvalue must exceed this fraction of the stiffness scale (see `check_modes`).
MIN_EIGENVALUE_RATIO = 1e-13

MECHANISM_MESSAGE = (
    "The modal analysis of a designed body found a rigid-body or mechanism mode, or an eigenvalue lost in "
    "round-off (non-finite modes, a solver that did not converge, or a lowest retained omega^2 below 1e-13 of "
    "the body's stiffness scale, the largest element ratio E_e tr(K_e) / (rho_e tr(M_e))): a piece of the mesh "
    "that is detached or hinged at a single node, reference conditions that do not remove the rigid-body "
    "motions, or elements so slender or distorted that the stiffness matrix is numerically singular. Check the "
    "mesh (connected, elements sharing edges, aspect ratios well below 1e3) and the reference conditions."
)


def stiffness_scale(model: FEModel | SolidFEModel, youngs, densities):
    """`max_e E_e tr(K_e) / (rho_e tr(M_e))`: within a small factor of the largest eigenvalue `omega_max^2`.

    Each element's ratio is a mean of its Rayleigh quotients, so it lies below that element's
    largest eigenvalue, and the assembled largest eigenvalue is bounded by the largest element
    eigenvalue (Irons' bound); on the rods here `omega_max^2` is 4 to 6 times this scale.
    """
    trace_k = jnp.trace(model.unit_stiffness, axis1=1, axis2=2)
    trace_m = jnp.trace(model.unit_mass, axis1=1, axis2=2)
    return jnp.max(youngs * trace_k / (densities * trace_m))


def check_modes(eigenvalues, modes, what: str, scale):
    """Raise at run time (`error_if`, a [`DesignError`][]) on non-finite modes, or a lowest retained eigenvalue
    that is not clearly positive: below `MIN_EIGENVALUE_RATIO * scale` (`scale` from [`stiffness_scale`][]).

    The check guards the eigenvalues *and* the modes (one `error_if` on both), so it runs on every path
    that uses either: the body data of an objective or gradient use only the modes.

    An eigenvalue of a generalized symmetric problem is computed with an absolute error of about
    `eps omega_max^2`, i.e. about `1e-15 scale` (`omega_max^2` is 4 to 6 times the scale): a rigid-body or
    mechanism mode (a detached piece, a flap hinged at one node) comes out at `+-3e-16 scale`, a rod of
    elements with aspect ratio 1e6 at `5e-15 scale` (Q4) or negative (QM6), where round-off decides its
    value and sign. Above `1e-13 scale` (about 100 `eps omega_max^2`) the lowest eigenvalue carries two
    or more correct digits. Healthy bodies sit far above: the 100 x 6 reference rod at 1.6e-7 (uniform
    0.5), 2.3e-10 (uniform x_min, where SIMP's mass law makes the void elements' ratio the scale) and
    3e-11 (random densities cubed, half of them near x_min); the link and two-link cases at 1e-10 or more.

    **Returns:** `(eigenvalues, modes)`.
    """
    bad = (~jnp.all(jnp.isfinite(modes)) | ~jnp.all(jnp.isfinite(eigenvalues))
           | ~(eigenvalues[0] > MIN_EIGENVALUE_RATIO * scale))
    return error_if((eigenvalues, modes), bad, f"{what}: {MECHANISM_MESSAGE}", DesignError)


def check_size(layout: ReductionLayout | SolidReductionLayout, n_modes: int, margin: int, what: str) -> None:
    if not isinstance(n_modes, int) or not 0 < n_modes < layout.n_interior - margin:
        raise ValueError(
            f"n_modes={n_modes} must be a positive int smaller than the number of interior degrees of freedom "
            f"({layout.n_interior}) minus {margin} for {what}; the derivative of the retained subspace needs "
            "discarded modes."
        )
