"""Assembly of the global matrices of a solid part: matrix-free, JAX BCOO, dense, and SciPy CSC on the host.

The 3D counterpart of [`FEModel`][] and its assembly: every global matrix has the form

`A(x) = sum_e v_e(x) P_e^T A_e P_e`,

one unit element matrix `A_e` per element (stiffness for `E = 1`, mass for `rho = 1`) scaled by
an element value `v_e` (Young's modulus `E_e = x_e^p E0` or mass density `rho_e` from [`SIMP`][]),
three degrees of freedom per node. [`SolidFEModel`][] holds the unit matrices as pytree leaves;
`SolidOperator` applies `A` without forming it, `solid_bcoo` forms it as a JAX sparse
BCOO matrix (differentiable in `v`), `solid_dense_matrix` densely for small parts, and
`solid_csc_matrices` as SciPy CSC matrices on the host for sparse factorisations (one cached
sparsity pattern per mesh and set of removed degrees of freedom).

Pass a `SolidFEModel` to compiled functions as an argument (not closed over), as for `FEModel`.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jax.experimental import sparse as jsparse
from jaxtyping import Array, Float, Int

from .element.solid_base import AbstractSolidElement, check_poisson
from .solid_mesh import SolidMesh

KINDS = ("stiffness", "mass")


class SolidFEModel(eqx.Module):
    """A discretised solid part: mesh, element type, and the unit element matrices as arrays.

    **Arguments:**
    - `mesh`: the [`SolidMesh`][] (static, hashable by content).
    - `element`: [`H8`][], [`H11`][] (hexahedral meshes) or [`Tet10`][] (tetrahedral meshes); static.
    - `poisson`: Poisson ratio in `[0, 0.5)` (default 0.3).

    **Fields (pytree leaves):** `coordinates` `(n_nodes, 3)`, `element_dofs` `(n_elements, d)`,
    `unit_stiffness` and `unit_mass` `(n_elements, d, d)`, `d = 3 x nodes per element`.
    """

    mesh: SolidMesh = eqx.field(static=True)
    element: AbstractSolidElement = eqx.field(static=True)
    poisson: float = eqx.field(static=True)
    coordinates: Float[Array, "n_nodes 3"]
    element_dofs: Int[Array, "n_elements d"]
    unit_stiffness: Float[Array, "n_elements d d"]
    unit_mass: Float[Array, "n_elements d d"]

    def __init__(self, mesh: SolidMesh, element: AbstractSolidElement, poisson: float = 0.3):
        if not isinstance(mesh, SolidMesh):
            raise TypeError(f"mesh must be a SolidMesh (box_grid, read_solid_mesh), got {type(mesh).__name__}.")
        mesh.check_element(element)
        poisson = check_poisson(poisson)
        k, m = element.matrices(mesh.element_coordinates(), poisson)
        self.mesh, self.element, self.poisson = mesh, element, poisson
        self.coordinates = jnp.asarray(mesh.nodes)
        self.element_dofs = jnp.asarray(mesh.element_dofs(), dtype=jnp.int32)
        self.unit_stiffness = jnp.asarray(k)
        self.unit_mass = jnp.asarray(m)

    @property
    def n_dof(self) -> int:
        return self.mesh.n_dof

    @property
    def n_elements(self) -> int:
        return self.mesh.n_elements

    def unit_matrices(self, kind: str) -> Float[Array, "n_elements d d"]:
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}.")
        return self.unit_stiffness if kind == "stiffness" else self.unit_mass

    def stiffness(self, youngs) -> "SolidOperator":
        """Matrix-free `K = sum_e E_e K_e` for element Young's moduli `(n_elements,)`."""
        return SolidOperator(self, youngs, "stiffness")

    def mass(self, densities) -> "SolidOperator":
        """Matrix-free consistent `M = sum_e rho_e M_e` for element mass densities `(n_elements,)`."""
        return SolidOperator(self, densities, "mass")


def _check_values(model: SolidFEModel, values, kind: str):
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}.")
    if jnp.shape(values) != (model.n_elements,):
        raise ValueError(f"The {kind} needs one value per element, shape ({model.n_elements},), got "
                         f"{jnp.shape(values)}.")


class SolidOperator(eqx.Module):
    """The global matrix `A = sum_e v_e P_e^T A_e P_e` of a solid part, applied without forming it.

    - `model`: the [`SolidFEModel`][]; `values`: `(n_elements,)` the scale `v_e`;
      `kind`: `"stiffness"` or `"mass"` (static).

    `A @ v` works for `v` of shape `(n_dof,)` or `(n_dof, k)`; memory and time linear in the number
    of elements, differentiable in `values` and `v`.
    """

    model: SolidFEModel
    values: Float[Array, " n_elements"]
    kind: str = eqx.field(static=True)

    def __check_init__(self):
        _check_values(self.model, self.values, self.kind)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.model.n_dof, self.model.n_dof)

    def __matmul__(self, v):
        v = jnp.asarray(v)
        if v.ndim not in (1, 2) or v.shape[0] != self.model.n_dof:
            raise ValueError(f"SolidOperator of shape {self.shape} cannot multiply an array of shape {v.shape}.")
        k = 1 if v.ndim == 1 else v.shape[1]
        dofs = self.model.element_dofs
        local = v.reshape(self.model.n_dof, -1)[dofs]
        local = self.values[:, None, None] * jnp.einsum("eab,ebk->eak", self.model.unit_matrices(self.kind), local)
        out = jax.ops.segment_sum(local.reshape(-1, k), dofs.ravel(), num_segments=self.model.n_dof)
        return out.reshape(v.shape)


def _entries(model: SolidFEModel):
    dofs = model.element_dofs
    d = dofs.shape[1]
    rows = jnp.repeat(dofs, d, axis=1).ravel()
    cols = jnp.tile(dofs, (1, d)).ravel()
    return rows, cols, d


def solid_bcoo(model: SolidFEModel, values, kind: str) -> jsparse.BCOO:
    """`sum_e v_e P_e^T A_e P_e` as a JAX sparse `BCOO` matrix `(n_dof, n_dof)`.

    One stored entry per element-matrix entry (`n_elements d^2`, duplicates not summed: products
    and transposes of BCOO handle them); differentiable in `values`.
    """
    _check_values(model, values, kind)
    rows, cols, _ = _entries(model)
    data = (values[:, None, None] * model.unit_matrices(kind)).ravel()
    return jsparse.BCOO((data, jnp.stack([rows, cols], axis=1)), shape=(model.n_dof, model.n_dof))


def solid_dense_matrix(model: SolidFEModel, values, kind: str) -> Float[Array, "n_dof n_dof"]:
    """Dense assembly `sum_e v_e P_e^T A_e P_e`, `(n_dof, n_dof)` (small parts only)."""
    _check_values(model, values, kind)
    rows, cols, _ = _entries(model)
    vals = (values[:, None, None] * model.unit_matrices(kind)).ravel()
    return jnp.zeros((model.n_dof, model.n_dof), dtype=vals.dtype).at[rows, cols].add(vals)


# --- host side: SciPy CSC matrices on a subset of the degrees of freedom ------------------------


class SolidCscPattern:
    """CSC sparsity pattern of a solid mesh's matrices with the degrees of freedom `removed` deleted.

    `position[k]` is where entry `k` of the flat element-matrix list (row-major, entries touching
    a removed degree of freedom dropped by `keep`) lands in the CSC data array, so that a matrix
    costs one `bincount`.
    """

    def __init__(self, mesh: SolidMesh, removed: tuple[int, ...]):
        self.kept = np.setdiff1d(np.arange(mesh.n_dof), np.asarray(removed, dtype=np.int64))
        self.n = self.kept.size
        renumber = np.full(mesh.n_dof, -1, dtype=np.int64)
        renumber[self.kept] = np.arange(self.n)
        local = renumber[mesh.element_dofs()]
        d = local.shape[1]
        self.entries_per_element = d * d
        rows = np.repeat(local, d, axis=1).ravel()
        cols = np.tile(local, (1, d)).ravel()
        self.keep = (rows >= 0) & (cols >= 0)
        keys = cols[self.keep] * self.n + rows[self.keep]
        unique, self.position = np.unique(keys, return_inverse=True)
        self.indices = (unique % self.n).astype(np.int32)
        self.indptr = np.searchsorted(unique // self.n, np.arange(self.n + 1)).astype(np.int32)
        self.nnz = unique.size

    def matrix(self, values: np.ndarray, unit: np.ndarray) -> sp.csc_matrix:
        """`sum_e v_e A_e` on the kept degrees of freedom, `(n, n)` CSC."""
        entries = (np.asarray(values)[:, None] * np.asarray(unit).reshape(-1, self.entries_per_element)).ravel()
        data = np.bincount(self.position, weights=entries[self.keep], minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


@functools.lru_cache(maxsize=8)
def solid_csc_pattern(mesh: SolidMesh, removed: tuple[int, ...]) -> SolidCscPattern:
    """The (cached) `SolidCscPattern` of `mesh` without the degrees of freedom `removed`."""
    return SolidCscPattern(mesh, tuple(sorted(int(d) for d in removed)))


def solid_csc_matrices(model: SolidFEModel, youngs, densities,
                       removed: tuple[int, ...] = ()) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """Host `K` and `M` of a solid part as SciPy CSC matrices on the degrees of freedom not in `removed`.

    **Arguments:** `model`; `youngs`, `densities`: `(n_elements,)` element values (NumPy or JAX
    arrays with values, not traced); `removed`: degrees of freedom to delete (held ones).

    **Returns:** `(K, M)`, `scipy.sparse.csc_matrix` of shape `(n_kept, n_kept)`.
    """
    for name, v in (("youngs", youngs), ("densities", densities)):
        if np.shape(v) != (model.n_elements,):
            raise ValueError(f"{name} needs one value per element, shape ({model.n_elements},), got {np.shape(v)}.")
    pattern = solid_csc_pattern(model.mesh, tuple(removed))
    return (pattern.matrix(np.asarray(youngs), np.asarray(model.unit_stiffness)),
            pattern.matrix(np.asarray(densities), np.asarray(model.unit_mass)))
