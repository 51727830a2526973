"""The flexible rod of REFERENCE_CASE §1–2 as a designed body (the cases' flexible part)."""

import numpy as np

from .._design.assembly import FEModel
from .._design.designed_body import DesignedBody
from .._design.element.q4 import Q4
from .._design.geometry import rod_domain, rod_joint_nodes
from .._design.material import SIMP
from .._design.modal.auto import AutoModes
from .._design.modal.base import AbstractModalSolver
from .._design.modal.reduction import ModalReduction
from .._design.modal.reference import HingedHinged


def rod_body(nx: int = 100, ny: int = 6, n_modes: int = 6, *, length: float = 1.0, height: float = 0.06,
             thickness: float = 0.01, poisson: float = 0.3, material: SIMP = SIMP(),
             modal_solver: AbstractModalSolver = AutoModes()) -> DesignedBody:
    """The rod of REFERENCE_CASE §1–2: an `nx x ny` grid of Q4 elements over `[0, L] x [-h/2, h/2]`,
    the first and last element columns solid, `n_modes` hinged–hinged modes, markers A and B.

    Design variables in REFERENCE_CASE order (`x.reshape(ny, nx - 2)[j, i - 1]`); marker 0 is
    `A = (0, 0)`, marker 1 is `B = (L, 0)`; the modes hold `u_x(A)`, `u_y(A)`, `u_y(B)`.

    **Arguments:**
    - `nx`, `ny`: elements along and across the rod (`nx >= 4`, `ny` even); `n_modes`: retained modes.
    - `length`, `height`, `thickness`, `poisson`: the rod; `material`: the SIMP law.
    - `modal_solver`: [`AutoModes`][] (default: dense up to 1,000 degrees of freedom, Lanczos
      above, so the reference rod takes [`LanczosModes`][]), [`DenseModes`][] or [`LanczosModes`][];
      all give the same numbers, only the dense solver supports forward mode in `x`.

    **Returns:** a [`DesignedBody`][].
    """
    # NumPy integers (np.int64(12), a value from np.arange) are integers too; as Python ints they hash as
    # the static mesh sizes and mode counts of the compiled programs.
    nx, ny, n_modes = (int(v) if isinstance(v, np.integer) else v for v in (nx, ny, n_modes))
    if not isinstance(nx, int) or nx < 4:
        raise ValueError(f"nx must be at least 4 (two solid end columns and design columns), got {nx!r}.")
    a, b = rod_joint_nodes(nx, ny)
    domain = rod_domain(nx, ny, length, height)
    model = FEModel(domain.mesh, Q4(), thickness, poisson)
    reduction = ModalReduction(n_modes, HingedHinged(a, b), solver=modal_solver)
    return DesignedBody(model, domain, material, reduction, (a, b))
