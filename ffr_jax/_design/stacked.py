"""The designs of several bodies as one flat vector, and a density filter per body on it.

An optimiser sees one vector `x = (x_b1, x_b2, ...)` (bodies in the design map's sorted order);
the case sees the dict `{name: x_b}`. [`StackedDesigns`][] converts between the two, and
[`StackedFilter`][] applies each body's own [`DensityFilter`][] to its block (a block-diagonal
`H = diag(H_b)`), with the volume weights of the bodies' combined design area.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .design_map import DesignMap
from .filter import DensityFilter


class StackedDesigns(eqx.Module):
    """The layout of a dict design `{name: (n_b,)}` in one flat `(sum n_b,)` vector.

    **Arguments:**
    - `sizes`: `{name: n_b}`, e.g. `design_map.design_sizes`; or a [`DesignMap`][].
    """

    names: tuple[str, ...] = eqx.field(static=True)
    sizes: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, sizes):
        if isinstance(sizes, DesignMap):
            sizes = sizes.design_sizes
        if not isinstance(sizes, dict) or not sizes:
            raise TypeError(f"StackedDesigns takes {{body name: number of densities}} or a DesignMap, got {sizes!r}.")
        self.names = tuple(sorted(sizes))
        self.sizes = tuple(int(sizes[name]) for name in self.names)

    @property
    def n_design(self) -> int:
        return sum(self.sizes)

    @property
    def slices(self) -> dict[str, slice]:
        """`{name: slice}` of each body's block in the flat vector."""
        ends = np.cumsum((0,) + self.sizes)
        return {name: slice(int(ends[k]), int(ends[k + 1])) for k, name in enumerate(self.names)}

    def ravel(self, designs: dict):
        """`{name: (n_b,)}` -> `(n_design,)` (a `ValueError` naming a missing, extra or mis-shaped body)."""
        if not isinstance(designs, dict):
            raise TypeError(f"Expected a dict design {{name: densities}} for the bodies {list(self.names)}.")
        missing = [n for n in self.names if n not in designs]
        extra = [n for n in designs if n not in self.names]
        if missing or extra:
            raise ValueError(f"The design's bodies {sorted(designs)} differ from the designed bodies {list(self.names)}"
                             f" (missing: {missing}, extra: {extra}).")
        for name, n in zip(self.names, self.sizes):
            if jnp.shape(designs[name]) != (n,):
                raise ValueError(f"Design of body {name!r} has shape {jnp.shape(designs[name])}, expected ({n},).")
        return jnp.concatenate([jnp.asarray(designs[name], dtype=float) for name in self.names])

    def unravel(self, x) -> dict:
        """`(n_design,)` -> `{name: (n_b,)}`."""
        if jnp.shape(x) != (self.n_design,):
            raise ValueError(f"Flat design has shape {jnp.shape(x)}, expected ({self.n_design},) = the bodies "
                             f"{dict(zip(self.names, self.sizes))} stacked.")
        return {name: x[s] for name, s in self.slices.items()}


class StackedFilter(eqx.Module):
    """A density filter per body on the stacked design: `H = diag(H_b)` (each body filtered on its own mesh).

    Duck-compatible with [`DensityFilter`][] where the optimisation loop uses one (`filter(x)`,
    `filter.transpose(g)`, `filter.volume_weights()`), on flat stacked vectors.

    **Arguments:**
    - `filters`: `{name: DensityFilter}` for every designed body (the radius may differ per body).
    """

    layout: StackedDesigns
    filters: dict[str, DensityFilter]

    def __init__(self, filters: dict):
        if not isinstance(filters, dict) or not filters:
            raise TypeError("StackedFilter takes {body name: DensityFilter}.")
        for name, f in filters.items():
            if not isinstance(f, DensityFilter):
                raise TypeError(f"StackedFilter: the filter of body {name!r} must be a DensityFilter, got "
                                f"{type(f).__name__}.")
        self.filters = dict(filters)
        self.layout = StackedDesigns({name: f.weights.shape[0] for name, f in filters.items()})

    @classmethod
    def of(cls, design_map: DesignMap, radius) -> "StackedFilter":
        """One [`DensityFilter`][] per designed body, `radius` in element sizes (a float, or a dict by body)."""
        radii = radius if isinstance(radius, dict) else {name: radius for name in design_map.names}
        missing = [n for n in design_map.names if n not in radii]
        if missing:
            raise ValueError(f"No filter radius for the designed bodies {missing}.")
        return cls({name: DensityFilter(body, radii[name]) for name, body in design_map.bodies.items()})

    def _blocks(self, x, fn):
        parts = self.layout.unravel(x)
        return jnp.concatenate([fn(self.filters[name], parts[name]) for name in self.layout.names])

    def __call__(self, x):
        """Physical densities `H x`, `(n_design,)`."""
        return self._blocks(x, lambda f, v: f(v))

    def transpose(self, g):
        """`H^T g`, `(n_design,)`."""
        return self._blocks(g, lambda f, v: f.transpose(v))

    def volume_weights(self):
        """`c = n H^T a / sum(a)` over all bodies' design elements (`a` the element areas), so that `mean(c x)`
        is the area fraction of the physical densities of all designed bodies together."""
        total = sum(jnp.sum(self.filters[n].areas) for n in self.layout.names)
        n = self.layout.n_design
        return jnp.concatenate([n * self.filters[name].transpose(self.filters[name].areas) / total
                                for name in self.layout.names])
