"""Linear density filter `x_phys = H x` on any mesh (Bruns and Tortorelli 2001; Bourdin 2001)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int
from scipy.spatial import cKDTree

from .domain import DesignDomain


class DensityFilter(eqx.Module):
    """The cone density filter over the design elements of any mesh, a fixed sparse linear map.

    `x_phys_e = sum_i w_ei a_i x_i / sum_i w_ei a_i`,  `w_ei = max(0, r - d_ei)`,

    with `d_ei` the distance between the centroids of design elements `e` and `i` (divided by
    `scale` per axis, if given) and `a_i` the element areas (all equal on a uniform grid, where
    this is the filter of `ffr_jax._optimize._filter`). Rows of `H` sum to one, so `H` maps
    `[x_min, 1]^n` into itself. Passive elements (solid or void) carry no design variable and
    take no part: they neither enter nor receive a filtered density. A radius that reaches no
    neighbour (in particular `r = 0`) gives `H = I`.

    Gradients go through the transpose: for `psi(x) = psi_phys(H x)`,
    `grad_x psi = H^T grad_phys psi`. `H` is stored row-wise as padded neighbour lists
    (`neighbours[e, k]` an index, `weights[e, k]` its normalised weight; padding points at `e`
    with weight 0), leaves of the pytree.

    **Arguments:**
    - `domain`: the [`DesignDomain`][].
    - `radius`: `r >= 0`, in the mesh's length unit (or in units of `scale`).
    - `scale`: optional `(sx, sy)`: distances are measured in `(dx / sx, dy / sy)`, e.g. the
      element size of a grid so that the radius counts elements (`1.5`: the 8 nearest).

    !!! cite "References"
        T. E. Bruns, D. A. Tortorelli, Comput. Methods Appl. Mech. Eng. 190 (2001) 3443–3459.

        B. Bourdin, "Filters in topology optimization", Int. J. Numer. Methods Eng. 50 (2001)
        2143–2158.
    """

    radius: float = eqx.field(static=True)
    neighbours: Int[Array, "n_design n_neighbours"]
    weights: Float[Array, "n_design n_neighbours"]

    def __init__(self, domain: DesignDomain, radius: float, scale=None):
        if not (radius >= 0.0 and np.isfinite(radius)):
            raise ValueError(f"The filter radius must be a finite non-negative length, got {radius}; radius=0 means "
                             "no filtering.")
        centres = domain.design_centroids()
        if scale is not None:
            scale = np.asarray(scale, dtype=float)
            if scale.shape != (2,) or not np.all((scale > 0) & np.isfinite(scale)):
                raise ValueError(f"scale must be two positive lengths (sx, sy), got {scale}.")
            centres = centres / scale
        areas = domain.design_areas()
        n = centres.shape[0]
        rows = cKDTree(centres).query_ball_point(centres, r=radius) if radius > 0 else [[e] for e in range(n)]
        counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=n)
        owner = np.repeat(np.arange(n), counts)
        flat = np.concatenate([np.sort(np.asarray(r, dtype=np.int64)) for r in rows])
        distance = np.linalg.norm(centres[flat] - centres[owner], axis=1)
        w = (np.maximum(radius - distance, 0.0) if radius > 0 else np.ones(flat.size)) * areas[flat]
        w = w / np.bincount(owner, weights=w, minlength=n)[owner]
        width = int(counts.max())
        slot = np.arange(flat.size) - np.repeat(np.cumsum(counts) - counts, counts)
        neighbours = np.repeat(np.arange(n)[:, None], width, axis=1)
        weights = np.zeros((n, width))
        neighbours[owner, slot] = flat
        weights[owner, slot] = w
        self.radius = float(radius)
        self.neighbours = jnp.asarray(neighbours, dtype=jnp.int32)
        self.weights = jnp.asarray(weights)

    def __call__(self, x):
        """Physical densities `H x`, `(n_design,)`."""
        return jnp.sum(self.weights * x[self.neighbours], axis=1)

    def transpose(self, g):
        """`H^T g`: a gradient with respect to the physical densities pulled back to the design."""
        return jnp.zeros_like(g).at[self.neighbours].add(self.weights * g[:, None])

    def volume_weights(self):
        """Column sums `c = H^T 1`, so that `sum(H x) = sum(c x)`."""
        return self.transpose(jnp.ones(self.weights.shape[0], dtype=self.weights.dtype))

    def matrix(self) -> Float[Array, "n_design n_design"]:
        """`H` as a dense matrix (inspection and tests only)."""
        n = self.weights.shape[0]
        return jnp.zeros((n, n), dtype=self.weights.dtype).at[jnp.arange(n)[:, None], self.neighbours].add(self.weights)
