"""Linear density filter `x_phys = H x` on any mesh (Bruns and Tortorelli 2001; Bourdin 2001)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int
from scipy.spatial import cKDTree

from .designed_body import DesignedBody
from .domain import DesignDomain
from .mesh import StructuredGrid
from .solid_designed_body import SolidDesignedBody
from .solid_domain import SolidDesignDomain


class DensityFilter(eqx.Module):
    """The cone density filter over the design elements of any mesh, a fixed sparse linear map.

    `x_phys_e = sum_i w_ei a_i x_i / sum_i w_ei a_i`,  `w_ei = max(0, r - d_ei)`,

    with `d_ei` the distance between the centroids of design elements `e` and `i`, measured in
    units of `scale` per axis, and `a_i` the element areas (all equal on a uniform grid, where
    this is the classic cone filter). Rows of `H` sum to one, so `H` maps
    `[x_min, 1]^n` into itself. Passive elements (solid or void) carry no design variable and
    take no part: they neither enter nor receive a filtered density. A radius that reaches no
    neighbour (in particular `r = 0`) gives `H = I`.

    Gradients go through the transpose: for `psi(x) = psi_phys(H x)`,
    `grad_x psi = H^T grad_phys psi`. `H` is stored row-wise as padded neighbour lists
    (`neighbours[e, k]` an index, `weights[e, k]` its normalised weight; padding points at `e`
    with weight 0), leaves of the pytree.

    **Arguments:**
    - `domain`: the [`DesignDomain`][], or a [`DesignedBody`][] (its domain; e.g. `case.design`); or, for a
      solid part, a [`SolidDesignDomain`][] or [`SolidDesignedBody`][]: then centroids are 3-D, `a_i` the
      element volumes, `scale` three lengths (default `(h, h, h)`, `h` the cube root of the mean volume) and
      `scale=(1, 1, 1)` takes the radius in metres.
    - `radius`: `r >= 0`, in units of `scale` (by default: in element sizes).
    - `scale`: `(sx, sy)`: distances are measured in `(dx / sx, dy / sy)`. Default: the element
      size — `(L / nx, h / ny)` on a `StructuredGrid` (the rod: `1.5` reaches the 8 nearest
      elements, `r <= 1` gives `H = I`), and `(h, h)` with `h = sqrt(mean area)` of the design
      elements on any other mesh. `scale=(1, 1)` takes the radius in the mesh's length unit.

    **Example:**
    ```python
    filt = fj.DensityFilter(case.design, radius=1.5)   # 1.5 element sizes
    x_phys = filt(x)
    ```

    !!! cite "References"
        T. E. Bruns, D. A. Tortorelli, Comput. Methods Appl. Mech. Eng. 190 (2001) 3443–3459.

        B. Bourdin, "Filters in topology optimization", Int. J. Numer. Methods Eng. 50 (2001)
        2143–2158.
    """

    radius: float = eqx.field(static=True)
    neighbours: Int[Array, "n_design n_neighbours"]
    weights: Float[Array, "n_design n_neighbours"]
    areas: Float[Array, " n_design"]

    def __init__(self, domain: DesignDomain | DesignedBody | SolidDesignDomain | SolidDesignedBody, radius: float,
                 scale=None):
        if isinstance(domain, (DesignedBody, SolidDesignedBody)):
            domain = domain.domain
        if not isinstance(domain, (DesignDomain, SolidDesignDomain)):
            raise TypeError(f"DensityFilter takes a DesignDomain or a DesignedBody (e.g. case.design), or their solid "
                            f"counterparts, got {type(domain).__name__}.")
        if not (radius >= 0.0 and np.isfinite(radius)):
            raise ValueError(f"The filter radius must be a finite non-negative number of element sizes, got {radius}; "
                             "radius=0 means no filtering (1.5 takes the 8 nearest neighbours on a grid).")
        centres, areas = domain.design_centroids(), domain.design_areas()
        if scale is None:
            mesh = domain.mesh
            if isinstance(domain, SolidDesignDomain):
                scale = (np.cbrt(np.mean(areas)),) * 3
            else:
                scale = (mesh.dx, mesh.dy) if isinstance(mesh, StructuredGrid) else (np.sqrt(np.mean(areas)),) * 2
        scale = np.asarray(scale, dtype=float)
        dim = centres.shape[1]
        if scale.shape != (dim,) or not np.all((scale > 0) & np.isfinite(scale)):
            raise ValueError(f"scale must be {dim} positive lengths (one per axis of the mesh), got {scale}.")
        centres = centres / scale
        n = centres.shape[0]
        rows = cKDTree(centres).query_ball_point(centres, r=radius) if radius > 0 else [[e] for e in range(n)]
        counts = np.fromiter((len(r) for r in rows), dtype=np.int64, count=n)
        owner = np.repeat(np.arange(n), counts)
        flat = np.concatenate([np.sort(np.asarray(r, dtype=np.int64)) for r in rows])
        distance = np.linalg.norm(centres[flat] - centres[owner], axis=1)
        # A neighbour at distance r up to round-off (a grid neighbour at r = 1 element) gets weight 0 exactly.
        reach = radius - distance
        cone = np.where(reach > 1e-12 * radius, reach, 0.0) if radius > 0 else np.ones(flat.size)
        w = cone * areas[flat]
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
        self.areas = jnp.asarray(areas)

    def __call__(self, x):
        """Physical densities `H x`, `(n_design,)`."""
        return jnp.sum(self.weights * x[self.neighbours], axis=1)

    def transpose(self, g):
        """`H^T g`: a gradient with respect to the physical densities pulled back to the design."""
        return jnp.zeros_like(g).at[self.neighbours].add(self.weights * g[:, None])

    def volume_weights(self):
        """Volume weights `c = n H^T a / sum(a)` (`a` the element areas), so that `mean(c x)` is the true
        area fraction of the physical densities, `sum(a H x) / sum(a)`; `c = H^T 1` on a uniform grid."""
        return self.areas.shape[0] * self.transpose(self.areas) / jnp.sum(self.areas)

    def matrix(self) -> Float[Array, "n_design n_design"]:
        """`H` as a dense matrix (inspection and tests only)."""
        n = self.weights.shape[0]
        return jnp.zeros((n, n), dtype=self.weights.dtype).at[jnp.arange(n)[:, None], self.neighbours].add(self.weights)
