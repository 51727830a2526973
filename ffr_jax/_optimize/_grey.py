"""The grey share of a design: how far its physical densities are from a 0/1 layout."""

import jax
import jax.numpy as jnp

from .._typing import Scalar

# The band of intermediate densities (Sigmund's measure of non-discreteness counts the same elements).
GREY_LOW, GREY_HIGH = 0.1, 0.9


def grey_share(x_phys, *, areas=None, low: float = GREY_LOW, high: float = GREY_HIGH) -> Scalar:
    """The share of design elements whose physical density is grey, `low < x_phys < high`.

    `share = sum_e a_e [low < x_e < high] / sum_e a_e` over the design elements (`a_e = 1` unless
    `areas` are given: then the area share). A design vector holds the designed elements only, so
    passive elements (solid rims, bores, void regions) carry no density and are never counted. A
    0/1 design has share 0; the uniform start design `x = V` has share 1 for `low < V < high`.
    Pure `jax.numpy`, so it runs inside a compiled step.

    **Arguments:**
    - `x_phys`: `(n_design,)` physical densities (`fj.physical_densities(x, filter, projection, beta)`,
      not the design variables: the filter and projection decide what the structure is), or a dict
      `{body: (n_b,)}` (the share over all bodies' elements together).
    - `areas`: `(n_design,)` element areas (or a dict like `x_phys`) for the area share; `None` counts elements.
    - `low`, `high`: the grey band, `0 <= low < high <= 1` (default 0.1 and 0.9).

    **Returns:** the share in `[0, 1]`, a scalar.

    **Example:**
    ```python
    x_phys = fj.physical_densities(result.x, filt, projection, beta=32.0)
    print(f"{100 * fj.grey_share(x_phys):.1f} % grey")
    ```
    """
    if not 0.0 <= low < high <= 1.0:
        raise ValueError(f"grey_share needs 0 <= low < high <= 1, got low={low}, high={high}.")
    x = jnp.concatenate([jnp.ravel(jnp.asarray(v)) for v in jax.tree.leaves(x_phys)])
    grey = ((x > low) & (x < high)).astype(x.dtype)
    if areas is None:
        return jnp.mean(grey)
    a = jnp.concatenate([jnp.ravel(jnp.asarray(v, dtype=x.dtype)) for v in jax.tree.leaves(areas)])
    if a.shape != x.shape:
        raise ValueError(f"grey_share: {a.shape[0]} areas for {x.shape[0]} densities; give one area per design "
                         "element (e.g. case.design.domain.design_areas()).")
    return jnp.sum(a * grey) / jnp.sum(a)
