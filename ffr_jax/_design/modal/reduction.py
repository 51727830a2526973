"""The modal basis a user asks for: reference conditions, interfaces, number of modes, solver."""

import equinox as eqx

from ..assembly import FEModel
from ..mesh import QuadMesh
from .auto import AutoModes
from .base import AbstractModalSolver
from .basis import ModalBasis
from .interface import Interface, ReductionLayout, reduction_layout
from .reference import AbstractReference


class ModalReduction(eqx.Module):
    """Modal truncation of a flexible body: `n_modes` eigenmodes plus the interfaces' static modes.

    `Phi = [Phi_eig, Psi]`: the `n_modes` lowest eigenmodes of `K phi = omega^2 M phi` with the
    reference conditions and every interface held, mass-normalised, then the Craig–Bampton
    static modes of the interfaces ([`Interface`][]). Without interfaces this is the paper's
    modal truncation (REFERENCE_CASE §2 with [`HingedHinged`][]).

    The derivative with respect to the element values depends only on gaps between retained and
    discarded eigenvalues, so it stays finite and exact for span-invariant quantities when
    retained eigenvalues cross; static modes are solutions of linear systems (no gaps at all).

    **Arguments:**
    - `n_modes`: number of eigenmodes (static).
    - `reference`: reference conditions ([`HingedHinged`][], [`Clamped`][], [`FixedDofs`][]).
    - `interfaces`: a tuple of [`Interface`][]s (default none).
    - `solver`: [`DenseModes`][], [`LanczosModes`][] or [`AutoModes`][] (default).
    """

    n_modes: int = eqx.field(static=True)
    reference: AbstractReference
    interfaces: tuple[Interface, ...] = ()
    solver: AbstractModalSolver = AutoModes()

    def __check_init__(self):
        if not isinstance(self.n_modes, int) or self.n_modes < 1:
            raise ValueError(f"n_modes must be a positive int, got {self.n_modes!r}.")
        if not isinstance(self.reference, AbstractReference):
            raise TypeError(f"reference must be reference conditions such as HingedHinged(a, b), got {self.reference!r}.")
        if not isinstance(self.interfaces, tuple) or not all(isinstance(i, Interface) for i in self.interfaces):
            raise TypeError("interfaces must be a tuple of Interface objects.")
        if not isinstance(self.solver, AbstractModalSolver):
            raise TypeError(f"solver must be DenseModes(), LanczosModes() or AutoModes(), got {self.solver!r}.")

    def layout(self, mesh: QuadMesh) -> ReductionLayout:
        """Held, interface and interior degrees of freedom on `mesh` (checks every node index)."""
        return reduction_layout(mesh, self.reference.fixed_dofs(mesh), self.interfaces)

    def n_q(self, mesh: QuadMesh) -> int:
        """Number of shape vectors on `mesh`: eigenmodes plus static modes."""
        return self.n_modes + self.layout(mesh).n_static

    def __call__(self, model: FEModel, youngs, densities) -> ModalBasis:
        """The modal basis for element Young's moduli and mass densities `(n_elements,)` each."""
        layout = self.layout(model.mesh)
        lam, modes = self.solver.solve(model, youngs, densities, layout, self.n_modes)
        return ModalBasis(eigenvalues=lam, modes=modes, n_static=layout.n_static)
