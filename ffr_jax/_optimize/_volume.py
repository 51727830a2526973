"""The volume (mass-fraction) constraint and the exact projection onto it."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Design, Designs, Scalar
from .._design.filter import DensityFilter
from .._design.stacked import StackedFilter
from ._constraint import AbstractDesignConstraint, status
from ._projection import HeavisideProjection


def _design_areas(filter: DensityFilter | StackedFilter):
    """The areas (volumes) of the design elements a filter acts on, in design order."""
    if isinstance(filter, StackedFilter):
        return jnp.concatenate([filter.filters[name].areas for name in filter.layout.names])
    return filter.areas


class VolumeConstraint(AbstractDesignConstraint):
    """The feasible designs `{x : x_min <= x <= 1, mean(c x) = V}`, or the inequality `mean(c x) <= V`.

    `c` are the volume weights of the design variables. Without a filter `c = 1` and the
    constraint is `mean(x) = V`. With a density filter `c = H^T 1`, so that the constraint holds
    for the physical densities, `mean(H x) = mean(c x) = V`, which is the volume the structure
    actually has. Because the SIMP mass law (paper eq. 47) is linear in `x` above `x = 0.1`, `V`
    is also the mass fraction of the design domain as long as no element lies below 0.1.

    With a [`HeavisideProjection`][] the physical densities are `x_phys = P_beta(H x)`, the
    volume, their area fraction `sum(a P_beta(H x)) / sum(a)` (`a` the element areas), is nonlinear
    in `x`, and the constraint is held on it (`fraction` and `project` then take `beta`).

    **Arguments:**
    - `volume`: the target fraction `V`, in `(x_min, 1]`.
    - `x_min`: the lower bound of the densities (REFERENCE_CASE §1: 0.01; `case.material.x_min`).
    - `filter`: the [`DensityFilter`][] between design and physical densities, if any; a dict
      `{body: DensityFilter}` for a design of several bodies (a dict by body) whose volume they
      share: `sum_b a_b . P(H_b x_b) / sum_b sum(a_b)` (`a_b` the element areas), an inequality
      for [`MMA`][] (a bound per body: [`OnBody`][] around a one-body constraint); or a
      [`StackedFilter`][] for the same bodies' designs stacked into one vector (an optax loop
      with the projection onto the shared volume).
    - `projection`: the [`HeavisideProjection`][] after the filter, if any.
    - `iterations`: bisection steps of [`VolumeConstraint.project`][] (100 reach the float64
      resolution of the multiplier from any bracket the design can produce).
    - `name`: the label of the constraint in logs and plots.
    """

    volume: float = eqx.field(static=True)
    x_min: float = eqx.field(static=True)
    iterations: int = eqx.field(static=True)
    weights: Float[Array, " n_design"] | dict[str, Float[Array, " _n"]] | None
    filter: DensityFilter | StackedFilter | dict[str, DensityFilter] | None
    projection: HeavisideProjection | None
    name: str = eqx.field(static=True)

    def __init__(self, volume: float, *, x_min: float = 0.01,
                 filter: DensityFilter | StackedFilter | dict[str, DensityFilter] | None = None,
                 projection: HeavisideProjection | None = None, iterations: int = 100, name: str = "volume"):
        if not 0.0 < x_min < 1.0:
            raise ValueError(f"x_min must lie in (0, 1), got {x_min}.")
        if not x_min < volume <= 1.0:
            raise ValueError(
                f"The volume fraction must lie in (x_min, 1] = ({x_min}, 1], got {volume}: at V = x_min "
                "every element would be void, and V > 1 cannot be reached with densities <= 1."
            )
        self.volume = float(volume)
        self.x_min = float(x_min)
        self.iterations = int(iterations)
        if projection is not None and projection.x_min != self.x_min:
            raise ValueError(f"The projection's x_min {projection.x_min} differs from the constraint's {self.x_min}.")
        if isinstance(filter, dict):
            # Several bodies sharing one volume: mean(c x) over all their design variables is the
            # area fraction sum_b a_b . (H_b x_b) / sum_b sum(a_b), so c_b = N H_b^T a_b / sum(a).
            total = sum(float(jnp.sum(f.areas)) for f in filter.values())
            count = sum(int(f.areas.shape[0]) for f in filter.values())
            self.weights = {name: count * f.transpose(f.areas) / total for name, f in filter.items()}
        else:
            self.weights = None if filter is None else filter.volume_weights()
        self.filter = filter
        self.projection = projection
        self.name = name

    def _check_beta(self, beta):
        if self.projection is not None and beta is None:
            raise ValueError("This volume constraint holds on projected densities: pass the projection's beta.")
        if self.projection is None and beta is not None:
            raise ValueError("beta was given, but this volume constraint has no projection.")

    def fraction(self, x: Designs, beta: Scalar | float | None = None) -> Scalar:
        """The volume fraction of a design's physical densities: `mean(c x)`, or `mean(P_beta(H x))`
        with a projection."""
        self._check_beta(beta)
        if isinstance(self.filter, dict):
            return self._shared_fraction(x, beta)
        if self.projection is not None:
            if self.filter is None:
                return jnp.mean(self.projection(x, beta))
            # The area fraction of the projected densities, as `mean(c x)` is without a projection (on an
            # unstructured mesh the plain mean of the elements is not the volume).
            areas = _design_areas(self.filter)
            return jnp.sum(areas * self.projection(self.filter(x), beta)) / jnp.sum(areas)
        return jnp.mean(x if self.weights is None else self.weights * x)

    def physical(self, x: Designs, beta: Scalar | float | None = None) -> Designs:
        """The physical densities this constraint measures: `x`, `H x` or `P_beta(H x)` (a dict by body for a
        volume shared by several bodies)."""
        self._check_beta(beta)
        if isinstance(self.filter, dict):
            return {b: self._one_physical(self.filter[b], x[b], beta) for b in sorted(self.filter)}
        return self._one_physical(self.filter, x, beta)

    def _one_physical(self, filter, x, beta):
        x_filtered = x if filter is None else filter(x)
        return x_filtered if self.projection is None else self.projection(x_filtered, beta)

    def _shared_fraction(self, x, beta):
        """The area fraction of the physical densities of several bodies (`x` and `filter` dicts by body)."""
        if not isinstance(x, dict) or set(x) != set(self.filter):
            raise ValueError(f"This volume is shared by the bodies {sorted(self.filter)}: pass their design as a dict "
                             f"with exactly these keys, got {sorted(x) if isinstance(x, dict) else type(x).__name__}.")
        if self.projection is None:
            count = sum(w.shape[0] for w in self.weights.values())
            return sum(jnp.sum(self.weights[b] * x[b]) for b in sorted(x)) / count
        area = sum(jnp.sum(f.areas) for f in self.filter.values())
        return sum(jnp.sum(self.filter[b].areas * self.projection(self.filter[b](x[b]), beta)) for b in sorted(x)) / area

    def value_and_grad(self, x: Designs, beta: Scalar | float | None = None):
        """`(g, dg/dx)` of the inequality `g(x) = fraction(x) / V - 1 <= 0`."""
        fraction, grad = jax.value_and_grad(lambda x: self.fraction(x, beta))(x)
        return fraction / self.volume - 1.0, jax.tree.map(lambda g: g / self.volume, grad)

    def describe(self, g: float) -> str:
        return f"volume fraction {self.volume * (1.0 + g):.6f} (bound <= {self.volume:g}): {status(g)}"

    def project(self, y: Design, beta: Scalar | float | None = None) -> Design:
        """Euclidean projection of `y` onto the feasible set (without a Heaviside projection).

        The KKT conditions of `min |x - y|^2 / 2` subject to the bounds and `mean(c x) = V`
        give `x(lambda) = clip(y - lambda c, x_min, 1)`, where the volume
        `g(lambda) = mean(c x(lambda))` is continuous and non-increasing. The multiplier is found
        by bisection between `lambda_lo = min((y - 1) / c)` (every `x_e = 1`, `g = 1 >= V`) and
        `lambda_hi = max((y - x_min) / c)` (every `x_e = x_min`, `g = x_min < V`), for a fixed
        number of steps, which keeps the map jit- and vmap-friendly. The volume then holds to a
        few units of float64 round-off.

        With a Heaviside projection the same family `x(lambda) = clip(y - lambda c, x_min, 1)` is
        searched for the multiplier with `mean(P_beta(H x(lambda))) = V`: `H` has non-negative
        entries and `P_beta` is increasing, so this volume is still continuous and non-increasing in
        `lambda`, the bracket still holds (`P_beta(1) = 1`, `P_beta(x_min) = x_min`), and the
        result meets the physical volume exactly. It is then a shift of `y` along `-c` onto the
        constraint rather than the Euclidean projection, which the nonlinear constraint has no
        closed form for.

        **Arguments:**
        - `y`: `(n_design,)` any real vector (e.g. a design after an optimizer update).
        - `beta`: the projection's sharpness (only with a projection).

        **Returns:** the feasible design, `(n_design,)` (without a projection: the closest to `y`).
        """
        self._check_beta(beta)
        if isinstance(self.filter, dict):
            raise ValueError("A volume shared by several bodies is an inequality for fj.MMA; the projection of Adam "
                             "and OC holds the volume of one design vector.")
        c = jnp.ones_like(y) if self.weights is None else self.weights

        def x_of(lam):
            return jnp.clip(y - lam * c, self.x_min, 1.0)

        def fraction_of(lam):
            x = x_of(lam)
            return jnp.mean(c * x) if self.projection is None else self.fraction(x, beta)

        def bisect(_, bracket):
            lo, hi = bracket
            mid = 0.5 * (lo + hi)
            above = fraction_of(mid) > self.volume
            return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

        bracket = (jnp.min((y - 1.0) / c), jnp.max((y - self.x_min) / c))
        lo, hi = jax.lax.fori_loop(0, self.iterations, bisect, bracket)
        return x_of(0.5 * (lo + hi))
