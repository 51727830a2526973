"""Linear density filter `x_phys = H x` over the design grid (Bruns and Tortorelli 2001)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int
from scipy.spatial import cKDTree

from .._simp import RodDesign
from .._typing import Design


class DensityFilter(eqx.Module):
    """The cone (linear hat) density filter, a fixed sparse linear map of the design vector.

    `x_phys_e = sum_i w_ei x_i / sum_i w_ei` with `w_ei = max(0, r - d_ei)`, where `d_ei` is the
    distance between the centres of design elements `e` and `i` measured in element sizes
    (`dx` along the rod, `dy` across it), so that a radius covers the same stencil whatever the
    aspect ratio of the elements. Rows of `H` sum to one, so `H` maps `[x_min, 1]^n` into itself.
    A radius `r <= 1` leaves every element alone (`H = I`). The solid interface columns carry no
    design variable and take no part.

    Gradients go through the transpose: for `psi(x) = psi_phys(H x)`,
    `grad_x psi = H^T grad_phys psi`.

    `H` is stored row-wise as padded neighbour lists: `neighbours[e, k]` is an element index and
    `weights[e, k]` its normalised weight (padding points at `e` itself with weight 0).

    **Arguments:**
    - `design`: the design layout of the rod (`case.design`).
    - `radius`: filter radius `r >= 0` in element sizes (`1.5` reaches the 8 nearest elements).

    **Returns:** a filter; `filter(x)` is `H x`, `filter.transpose(g)` is `H^T g`.

    **Example:**
    ```python
    filt = fj.DensityFilter(case.design, radius=1.5)
    x_phys = filt(x)
    ```

    !!! cite "Reference"
        T. E. Bruns, D. A. Tortorelli, "Topology optimization of non-linear elastic structures and
        compliant mechanisms", Comput. Methods Appl. Mech. Eng. 190 (2001) 3443–3459.
    """

    radius: float = eqx.field(static=True)
    neighbours: Int[Array, "n_design n_neighbours"]
    weights: Float[Array, "n_design n_neighbours"]

    def __init__(self, design: RodDesign, radius: float):
        if not (radius >= 0.0 and np.isfinite(radius)):
            raise ValueError(
                f"The filter radius must be a finite non-negative number of element sizes, got {radius}; "
                "use radius=0 for no filtering (or 1.5 for the 8 nearest neighbours)."
            )
        mesh = design.mesh
        scaled = design.design_centres() / np.array([mesh.dx, mesh.dy])
        n = scaled.shape[0]
        if radius <= 1.0:
            neighbour_lists = [[e] for e in range(n)]
        else:
            neighbour_lists = cKDTree(scaled).query_ball_point(scaled, r=radius)
        width = max(len(row) for row in neighbour_lists)
        neighbours = np.repeat(np.arange(n)[:, None], width, axis=1)
        weights = np.zeros((n, width))
        for e, row in enumerate(neighbour_lists):
            row = np.asarray(sorted(row))
            distance = np.linalg.norm(scaled[row] - scaled[e], axis=1)
            w = np.maximum(radius - distance, 0.0) if radius > 1.0 else np.ones(1)
            neighbours[e, : len(row)] = row
            weights[e, : len(row)] = w / w.sum()
        self.radius = float(radius)
        self.neighbours = jnp.asarray(neighbours)
        self.weights = jnp.asarray(weights)

    def __call__(self, x: Design) -> Design:
        """Physical densities `H x`."""
        return jnp.sum(self.weights * x[self.neighbours], axis=1)

    def transpose(self, g: Design) -> Design:
        """`H^T g`: a gradient with respect to the physical densities pulled back to the design."""
        return jnp.zeros_like(g).at[self.neighbours].add(self.weights * g[:, None])

    def volume_weights(self) -> Design:
        """Column sums `c = H^T 1`, so that `mean(H x) = mean(c x)` (the mean of `c` is 1)."""
        return self.transpose(jnp.ones(self.weights.shape[0], dtype=self.weights.dtype))

    def matrix(self) -> Float[Array, "n_design n_design"]:
        """`H` as a dense matrix (for inspection and tests; the filter itself never forms it)."""
        n = self.weights.shape[0]
        return jnp.zeros((n, n), dtype=self.weights.dtype).at[jnp.arange(n)[:, None], self.neighbours].add(
            self.weights
        )
