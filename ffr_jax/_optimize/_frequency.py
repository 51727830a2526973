"""A lower bound on a natural frequency of the designed body."""

import warnings

import equinox as eqx

from .._dynamics._case import Case
from .._typing import Design
from ._constraint import AbstractDesignConstraint, pullback, status
from .._design.filter import DensityFilter
from ._projection import HeavisideProjection

# Above this many degrees of freedom the dense eigen-solution of the bound check is skipped.
_BOUND_CHECK_MAX_DOF = 4000


class FrequencyConstraint(AbstractDesignConstraint):
    """`f_k(x) >= f_min` for the `k`-th natural frequency of the designed body (default the first).

    `f_k = omega_k / (2 pi)` are the hinged–hinged frequencies of the body that the case's modal
    basis uses (`case.frequencies`, REFERENCE_CASE §2) for the physical densities
    `x_phys = P_beta(H x)`. The constraint is `g = 1 - f_k / f_min <= 0`, with the gradient from
    the eigenvalue derivative `d lambda_k = phi_k^T (dK - lambda_k dM) phi_k` (exact for a simple
    eigenvalue; `case.frequencies` differentiates the retained modes, `ffr_jax.retained_eigenpairs`),
    pulled back through the projection and filter.

    **Which bounds can be met.** The solid body is *not* the stiffest in this sense: `f_1` is the
    Rayleigh quotient `min_v v^T K v / v^T M v`, and removing mass where it moves but carries
    little stiffness raises it (on the 24 x 4 rod a sandwich of two solid rows with webs every six
    columns has `f_1 = 78.0 Hz`, the solid rod 70.7 Hz). A bound that holds for *every* design
    follows from the same quotient: with `K(x) <= K(1)` (Young's modulus increasing in `x`) and
    `M(x) >= M(x_min)` (the SIMP density law increasing, the interface columns solid in every
    design), `lambda_1(x) <= R_x(v) <= v^T K(1) v / v^T M(x_min) v` for the first mode `v` of the
    pair `(K(1), M(x_min))`, so `f_1(x) <= f_1(K(1), M(x_min))` — a stiff body carrying only the
    least mass. A bound `f_min` at or above it is refused at construction (computed densely up to
    4,000 degrees of freedom). It is loose (kHz against tens of Hz: the end columns on a massless
    solid rod), so a bound between the reachable maximum and it is not caught at the start; a
    warning is given above the solid body's `f_1`, and the optimiser reports the infeasible end
    ([`OptimizeResult.feasible`][]).

    **Arguments:**
    - `case`: the [`Case`][] whose (one) body is designed.
    - `minimum`: `f_min` in Hz.
    - `mode`: which frequency, `0` for the first (it must be a retained mode).
    - `filter`, `projection`: the maps from design to physical densities (as for the objective).
    - `name`: the label in logs and plots.

    **Example:**
    ```python
    frequency = fj.FrequencyConstraint(case, 40.0, filter=filt)   # f_1 >= 40 Hz
    ```
    """

    case: Case
    minimum: float = eqx.field(static=True)
    mode: int = eqx.field(static=True)
    filter: DensityFilter | None
    projection: HeavisideProjection | None
    name: str = eqx.field(static=True)
    upper_bound: float = eqx.field(static=True)
    solid: float = eqx.field(static=True)

    def __init__(self, case: Case, minimum: float, *, mode: int = 0, filter: DensityFilter | None = None,
                 projection: HeavisideProjection | None = None, name: str = "frequency"):
        if not minimum > 0.0:
            raise ValueError(f"The frequency bound must be a positive number of Hz, got {minimum}.")
        if not 0 <= mode < case.n_modes:
            raise ValueError(f"mode={mode} is not a retained mode of the case (0 <= mode < {case.n_modes}).")
        self.case = case
        self.minimum = float(minimum)
        self.mode = int(mode)
        self.filter = filter
        self.projection = projection
        self.name = name
        self.solid = float(_frequencies(case, case.design.initial_design(1.0))[mode])
        self.upper_bound = float(_rayleigh_bound(case)) if mode == 0 and case.mesh.n_dof <= _BOUND_CHECK_MAX_DOF \
            else float("inf")
        if self.minimum >= self.upper_bound:
            raise ValueError(
                f"No design of this body reaches f_1 >= {self.minimum:g} Hz: every design has f_1 <= "
                f"{self.upper_bound:.6g} Hz (the solid stiffness with the least mass, a Rayleigh-quotient bound). "
                f"The solid body has f_1 = {self.solid:.6g} Hz. Lower the bound."
            )
        if self.minimum > self.solid:
            warnings.warn(
                f"The frequency bound {self.minimum:g} Hz lies above f_{mode + 1} = {self.solid:.6g} Hz of the solid "
                "body. "
                "Designs that take mass away where it moves but carries little stiffness can exceed the solid "
                "body's frequency, but perhaps not by this much: the run may end infeasible (check "
                "OptimizeResult.feasible).",
                stacklevel=4,  # past equinox's module construction, to the caller
            )

    def frequency(self, x_phys: Design):
        """`f_k` in Hz of the physical densities `x_phys` `(n_design,)`."""
        return self.case.frequencies(x_phys)[self.mode]

    def value_and_grad(self, x: Design, beta=None):
        f, grad = pullback(self.frequency, x, self.filter, self.projection, beta)
        return 1.0 - f / self.minimum, -grad / self.minimum

    def describe(self, g: float) -> str:
        f = self.minimum * (1.0 - g)
        return f"f_{self.mode + 1} {f:.6g} Hz (bound >= {self.minimum:g} Hz): {status(g)}"


@eqx.filter_jit
def _frequencies(case: Case, x):
    return case.frequencies(x)


@eqx.filter_jit
def _rayleigh_bound(case: Case):
    """`f_1` of the pair `(K(1), M(x_min))`: above `f_1` of every design (see [`FrequencyConstraint`][])."""
    design, material = case.design, case.material
    youngs = material.youngs(design.element_densities(design.initial_design(1.0)))
    densities = material.densities(design.element_densities(design.initial_design(material.x_min)))
    return design.reduction(design.model, youngs, densities).frequencies[0]
