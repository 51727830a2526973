"""The volume (mass-fraction) constraint and the exact projection onto it."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._typing import Design, Scalar
from .._design.filter import DensityFilter
from ._projection import HeavisideProjection


class VolumeConstraint(eqx.Module):
    """The feasible designs `{x : x_min <= x <= 1, mean(c x) = V}`.

    `c` are the volume weights of the design variables. Without a filter `c = 1` and the
    constraint is `mean(x) = V`. With a density filter `c = H^T 1`, so that the constraint holds
    for the physical densities, `mean(H x) = mean(c x) = V`, which is the volume the structure
    actually has. Because the SIMP mass law (paper eq. 47) is linear in `x` above `x = 0.1`, `V`
    is also the mass fraction of the design domain as long as no element lies below 0.1.

    With a [`HeavisideProjection`][] the physical densities are `x_phys = P_beta(H x)`, the
    volume `mean(P_beta(H x))` is nonlinear in `x`, and the constraint is held on it
    (`fraction` and `project` then take `beta`).

    **Arguments:**
    - `volume`: the target fraction `V`, in `(x_min, 1]`.
    - `x_min`: the lower bound of the densities (REFERENCE_CASE §1: 0.01; `case.material.x_min`).
    - `filter`: the [`DensityFilter`][] between design and physical densities, if any.
    - `projection`: the [`HeavisideProjection`][] after the filter, if any.
    - `iterations`: bisection steps of [`VolumeConstraint.project`][] (100 reach the float64
      resolution of the multiplier from any bracket the design can produce).
    """

    volume: float = eqx.field(static=True)
    x_min: float = eqx.field(static=True)
    iterations: int = eqx.field(static=True)
    weights: Float[Array, " n_design"] | None
    filter: DensityFilter | None
    projection: HeavisideProjection | None

    def __init__(self, volume: float, *, x_min: float = 0.01, filter: DensityFilter | None = None,
                 projection: HeavisideProjection | None = None, iterations: int = 100):
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
        self.weights = None if filter is None else filter.volume_weights()
        self.filter = filter
        self.projection = projection

    def _check_beta(self, beta):
        if self.projection is not None and beta is None:
            raise ValueError("This volume constraint holds on projected densities: pass the projection's beta.")
        if self.projection is None and beta is not None:
            raise ValueError("beta was given, but this volume constraint has no projection.")

    def fraction(self, x: Design, beta: Scalar | float | None = None) -> Scalar:
        """The volume fraction of a design's physical densities: `mean(c x)`, or `mean(P_beta(H x))`
        with a projection."""
        self._check_beta(beta)
        if self.projection is not None:
            x_filtered = x if self.filter is None else self.filter(x)
            return jnp.mean(self.projection(x_filtered, beta))
        return jnp.mean(x if self.weights is None else self.weights * x)

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
