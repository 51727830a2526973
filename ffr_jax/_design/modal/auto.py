"""Automatic choice of the modal solver by the size of the mesh."""

import equinox as eqx

from ..assembly import FEModel
from ..solid_assembly import SolidFEModel
from ..solid_layout import SolidReductionLayout
from .base import AbstractModalSolver
from .dense import DenseModes
from .interface import ReductionLayout
from .lanczos import LanczosModes


# Meshes with more degrees of freedom than this take LanczosModes. Measured on the reference rod
# (1,414 dofs, 6 modes, 2-core CPU): forward + VJP of the FE stage 0.30 s sparse vs 17-26 s dense
# (a full eigen-solution and its cubic derivative), equal to round-off (benchmarks/RESULTS.md).
MAX_DENSE_DOF = 1000


class AutoModes(AbstractModalSolver):
    """[`DenseModes`][] up to `max_dense_dof` degrees of freedom (default 1,000), else [`LanczosModes`][].

    The choice is made at trace time from the mesh size, so the reference rod (1,414 dofs) takes
    the Lanczos solver. Only the dense solver supports forward mode (`jax.jvp`).
    """

    max_dense_dof: int = eqx.field(static=True, default=MAX_DENSE_DOF)

    def choose(self, model: FEModel | SolidFEModel) -> AbstractModalSolver:
        """The solver this option takes on `model`."""
        return DenseModes() if model.n_dof <= self.max_dense_dof else LanczosModes()

    def solve(self, model: FEModel | SolidFEModel, youngs, densities, layout: ReductionLayout | SolidReductionLayout,
              n_modes: int):
        return self.choose(model).solve(model, youngs, densities, layout, n_modes)
