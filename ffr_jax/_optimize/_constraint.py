"""The abstract inequality constraint on the design, `g(x) <= 0`, and the pullback its subclasses share."""

import abc
from collections.abc import Callable

import equinox as eqx
import jax

from .._typing import Design
from .._design.filter import DensityFilter
from ._objective import physical_densities
from ._projection import HeavisideProjection


class AbstractDesignConstraint(eqx.Module):
    """An inequality constraint `g(x) <= 0` on the design `x`, with its exact gradient.

    `g` is normalised by its bound (`g = value / bound - 1` for an upper bound,
    `1 - value / bound` for a lower one), so that `g = 0.01` reads "1 % over the bound" whatever
    the units, and an optimizer's penalties ([`MMA`][]'s `c`) have one scale for all constraints.

    Final subclasses: [`VolumeConstraint`][], [`MassConstraint`][], [`FrequencyConstraint`][],
    [`FunctionConstraint`][].

    **Attributes:**
    - `name`: a short label for the log column (`g_<name>`), the plots and the messages.
    """

    name: eqx.AbstractVar[str]

    @abc.abstractmethod
    def value_and_grad(self, x: Design, beta=None):
        """`(g(x), dg/dx)`: a scalar and an array shaped like `x` (`beta`: the projection's sharpness,
        `None` without a projection)."""

    @abc.abstractmethod
    def describe(self, g: float) -> str:
        """A line for people: the constrained quantity recovered from `g`, its bound, and whether it holds."""


def pullback(fun: Callable, x: Design, filter: DensityFilter | None, projection: HeavisideProjection | None, beta):
    """`(f(x_phys), J^T grad f(x_phys))` for `f = fun` of the physical densities `x_phys = P_beta(H x)`.

    `fun` maps physical densities to a scalar (traceable); its gradient is taken by `jax.vjp` of
    the same map that made `x_phys`, so value and gradient are consistent.
    """
    x_phys, back = jax.vjp(lambda x: physical_densities(x, filter, projection, beta), x)
    value, grad = jax.value_and_grad(fun)(x_phys)
    return value, back(grad)[0]


def status(g: float, tolerance: float = 1e-6) -> str:
    """`"holds"` or `"VIOLATED by <g>"` for a normalised constraint value."""
    return "holds" if g <= tolerance else f"VIOLATED by {100 * g:.3g} %"
