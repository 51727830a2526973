"""A bound on the total mass of the designed body (SIMP density law, paper eq. 47)."""

import equinox as eqx
import jax.numpy as jnp

from .._design.designed_body import DesignedBody
from .._typing import Design, Scalar
from ._constraint import AbstractDesignConstraint, pullback, status
from .._design.filter import DensityFilter
from ._projection import HeavisideProjection


class MassConstraint(AbstractDesignConstraint):
    """`m(x) <= m_max` (or `m(x) >= m_min`) for the mass of the designed body.

    The mass of the body is

        m(x) = sum_e rho_e(x_e) V_e,   V_e = A_e t,

    over every element of the body: the design elements with their physical densities
    `x_phys = P_beta(H x)` and the solid interface columns (`x = 1`). `rho_e` is the SIMP density
    law of paper eq. 47 (`rho0 x` above `x_switch`, `c rho0 x^q` below), so `m` equals the mass
    `e_x^T M e_x` of the body's consistent mass matrix, and is not the volume: below
    `x_switch = 0.1` the mass falls off with `x^6`. The gradient is exact (`jax.grad` of the law,
    pulled back through the filter and projection).

    The constraint is `g = m / m_max - 1 <= 0` (or `g = 1 - m / m_min <= 0` with `lower=True`).
    A bound that no design can meet is refused at construction: an upper bound at or below the
    mass of the lightest design (every design element at `x_min`: the interface columns and the
    voids), or a lower bound above the mass of the solid body.

    **Arguments:**
    - `design`: the body's [`DesignedBody`][] (`case.design`).
    - `bound`: the mass bound in kg.
    - `lower`: `True` for a lower bound `m >= bound`.
    - `filter`, `projection`: the maps from design to physical densities (as for the objective).
    - `name`: the label in logs and plots.

    **Example:**
    ```python
    mass = fj.MassConstraint(case.design, 0.02, filter=filt)   # at most 20 g
    ```
    """

    design: DesignedBody
    bound: float = eqx.field(static=True)
    lower: bool = eqx.field(static=True)
    filter: DensityFilter | None
    projection: HeavisideProjection | None
    name: str = eqx.field(static=True)

    def __init__(self, design: DesignedBody, bound: float, *, lower: bool = False, filter: DensityFilter | None = None,
                 projection: HeavisideProjection | None = None, name: str = "mass"):
        self.design = design
        self.bound = float(bound)
        self.lower = bool(lower)
        self.filter = filter
        self.projection = projection
        self.name = name
        lightest, heaviest = self.range
        if not self.bound > 0.0:
            raise ValueError(f"The mass bound must be a positive number of kg, got {bound}.")
        if not self.lower and self.bound <= lightest:
            raise ValueError(
                f"No design can meet mass <= {self.bound:.6g} kg: the lightest design (every design element at "
                f"x_min = {design.material.x_min}, the solid interface columns kept) weighs {lightest:.6g} kg. "
                "Raise the bound."
            )
        if self.lower and self.bound > heaviest:
            raise ValueError(
                f"No design can meet mass >= {self.bound:.6g} kg: the solid body weighs {heaviest:.6g} kg. "
                "Lower the bound."
            )

    def mass(self, x_phys: Design) -> Scalar:
        """`m = sum_e rho_e V_e` of the physical densities `x_phys` `(n_design,)`, in kg."""
        return body_mass(self.design, x_phys)

    def value_and_grad(self, x: Design, beta=None):
        m, grad = pullback(self.mass, x, self.filter, self.projection, beta)
        if self.lower:
            return 1.0 - m / self.bound, -grad / self.bound
        return m / self.bound - 1.0, grad / self.bound

    def describe(self, g: float) -> str:
        m = self.bound * (1.0 - g if self.lower else 1.0 + g)
        return f"mass {m:.6g} kg (bound {'>=' if self.lower else '<='} {self.bound:.6g} kg): {status(g)}"

    @property
    def range(self) -> tuple[float, float]:
        """The masses of the lightest and of the solid design, in kg (every reachable mass lies between)."""
        d = self.design
        mass = eqx.filter_jit(body_mass)
        return float(mass(d, d.initial_design(d.material.x_min))), float(mass(d, d.initial_design(1.0)))


def body_mass(design: DesignedBody, x_phys: Design) -> Scalar:
    """`m = sum_e rho_e V_e` of a body with physical densities `x_phys` `(n_design,)` (SIMP law, paper eq. 47)."""
    densities = design.material.densities(design.element_densities(x_phys))
    areas = jnp.asarray(design.mesh.element_areas())  # host constants of the (static) mesh
    return jnp.sum(densities * areas) * design.model.thickness
