"""Assembly of global matrices on any quad mesh: dense, matrix-free, and SciPy CSC on the host.

Every global matrix of a designed body has the form

`A = sum_e v_e P_e^T A_e P_e`,

one unit element matrix `A_e` per element (stiffness for `E = 1`, mass for `rho = 1`; general
quadrilaterals differ element by element) scaled by the element value `v_e` (Young's modulus or
mass density). [`FEModel`][] holds the unit matrices and the element degrees of freedom as
pytree leaves; [`ElementOperator`][] applies `A` without forming it (memory and time linear in
the number of elements, differentiable in `v` and in the vector by ordinary autodiff);
[`dense_matrix`][] forms it for small meshes; [`csc_matrices`][] assembles it on the host as
SciPy CSC matrices for sparse factorisations, reusing one sparsity pattern per mesh and set of
removed degrees of freedom.

Pass an `FEModel` to compiled functions as an argument (`eqx.filter_jit(f)(model, x)`): its
arrays are then inputs of the program. Closed over (a `jax.jit` of a lambda or bound method
that captures it), they would be embedded as constants — for 10^5 elements, tens of megabytes
of HLO and minutes of compilation.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, Float, Int

from .element.base import AbstractElement
from .mesh import QuadMesh
from .solid_assembly import SolidFEModel

KINDS = ("stiffness", "mass")


class FEModel(eqx.Module):
    """A discretised plane body: mesh, element type, and the unit element matrices as arrays.

    **Arguments:**
    - `mesh`: the [`QuadMesh`][] (static, hashable by content).
    - `element`: the element ([`Q4`][] or [`QM6`][]; static).
    - `thickness`: out-of-plane thickness; `poisson`: Poisson ratio (plane stress).

    **Fields (pytree leaves):** `coordinates` `(n_nodes, 2)`, `element_dofs` `(n_elements, 8)`,
    `unit_stiffness` and `unit_mass` `(n_elements, 8, 8)`.
    """

    mesh: QuadMesh = eqx.field(static=True)
    element: AbstractElement = eqx.field(static=True)
    thickness: float = eqx.field(static=True)
    poisson: float = eqx.field(static=True)
    coordinates: Float[Array, "n_nodes 2"]
    element_dofs: Int[Array, "n_elements 8"]
    unit_stiffness: Float[Array, "n_elements 8 8"]
    unit_mass: Float[Array, "n_elements 8 8"]

    def __init__(self, mesh: QuadMesh, element: AbstractElement, thickness: float, poisson: float = 0.3):
        if not isinstance(mesh, QuadMesh):
            raise TypeError(f"mesh must be a QuadMesh, got {type(mesh).__name__}.")
        if not isinstance(element, AbstractElement):
            raise TypeError(f"element must be an element such as Q4() or QM6(), got {element!r}.")
        if not thickness > 0:
            raise ValueError(f"thickness must be positive, got {thickness}.")
        if not 0.0 <= poisson < 0.5:
            raise ValueError(f"Poisson ratio must lie in [0, 0.5), got {poisson}.")
        k, m = element.matrices(mesh.element_coordinates(), float(poisson), float(thickness))
        self.mesh, self.element = mesh, element
        self.thickness, self.poisson = float(thickness), float(poisson)
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

    def unit_matrices(self, kind: str) -> Float[Array, "n_elements 8 8"]:
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}.")
        return self.unit_stiffness if kind == "stiffness" else self.unit_mass

    def stiffness(self, youngs) -> "ElementOperator":
        """Matrix-free `K = sum_e E_e K_e` for element Young's moduli `(n_elements,)`."""
        return ElementOperator(self, youngs, "stiffness")

    def mass(self, densities) -> "ElementOperator":
        """Matrix-free consistent `M = sum_e rho_e M_e` for element mass densities `(n_elements,)`."""
        return ElementOperator(self, densities, "mass")


def element_vectors(model: FEModel, v):
    """Gather a global vector `(n_dof,)` or block `(n_dof, k)` onto the elements: `(n_elements, 8, k)`."""
    return v.reshape(model.n_dof, -1)[model.element_dofs]


def scatter(model: FEModel, local, k: int):
    """Sum element vectors `(n_elements, 8, k)` into a global block `(n_dof, k)`."""
    return jax.ops.segment_sum(local.reshape(-1, k), model.element_dofs.ravel(), num_segments=model.n_dof)


class ElementOperator(eqx.Module):
    """The global matrix `A = sum_e v_e P_e^T A_e P_e`, applied without forming it.

    - `model`: the [`FEModel`][]; `values`: `(n_elements,)` the scale `v_e`;
      `kind`: `"stiffness"` or `"mass"` (static).

    `A @ v` works for `v` of shape `(n_dof,)` or `(n_dof, k)`.
    """

    model: FEModel
    values: Float[Array, " n_elements"]
    kind: str = eqx.field(static=True)

    def __check_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"ElementOperator kind must be one of {KINDS}, got {self.kind!r}.")
        if self.values.shape != (self.model.n_elements,):
            raise ValueError(
                f"ElementOperator needs one value per element, shape ({self.model.n_elements},), got {self.values.shape}."
            )

    @property
    def shape(self) -> tuple[int, int]:
        return (self.model.n_dof, self.model.n_dof)

    def __matmul__(self, v):
        v = jnp.asarray(v)
        if v.ndim not in (1, 2) or v.shape[0] != self.model.n_dof:
            raise ValueError(f"ElementOperator of shape {self.shape} cannot multiply an array of shape {v.shape}.")
        k = 1 if v.ndim == 1 else v.shape[1]
        if k == 0:  # no columns (a rigid body's empty basis)
            return jnp.zeros(v.shape, jnp.result_type(self.values, v))
        local = element_vectors(self.model, v)
        local = self.values[:, None, None] * jnp.einsum("eab,ebk->eak", self.model.unit_matrices(self.kind), local)
        return scatter(self.model, local, k).reshape(v.shape)

    def todense(self) -> Float[Array, "n_dof n_dof"]:
        """The dense matrix (small meshes and tests)."""
        return dense_matrix(self.model, self.values, self.kind)


def dense_matrix(model: FEModel | SolidFEModel, values, kind: str) -> Float[Array, "n_dof n_dof"]:
    """Dense assembly `sum_e v_e P_e^T A_e P_e`, `(n_dof, n_dof)` (small meshes only; planar or solid models)."""
    dofs = model.element_dofs
    d = dofs.shape[1]
    rows = jnp.repeat(dofs, d, axis=1).ravel()
    cols = jnp.tile(dofs, (1, d)).ravel()
    vals = (values[:, None, None] * model.unit_matrices(kind)).ravel()
    return jnp.zeros((model.n_dof, model.n_dof), dtype=vals.dtype).at[rows, cols].add(vals)


# --- host side: SciPy CSC matrices on a subset of the degrees of freedom ------------------------


class CscPattern:
    """CSC sparsity pattern of the mesh's matrices with the degrees of freedom `removed` deleted.

    `position[k]` is where entry `k` of the flat element-matrix list (`(n_elements, 8, 8)`
    row-major, entries touching a removed degree of freedom dropped by `keep`) lands in the CSC
    data array, so a matrix costs one `bincount`.
    """

    def __init__(self, mesh: QuadMesh, removed: tuple[int, ...]):
        n_dof = mesh.n_dof
        self.kept = np.setdiff1d(np.arange(n_dof), np.asarray(removed, dtype=np.int64))
        self.n = self.kept.size
        renumber = np.full(n_dof, -1, dtype=np.int64)
        renumber[self.kept] = np.arange(self.n)
        local = renumber[mesh.element_dofs()]
        rows = np.repeat(local, 8, axis=1).ravel()
        cols = np.tile(local, (1, 8)).ravel()
        self.keep = (rows >= 0) & (cols >= 0)
        keys = cols[self.keep] * self.n + rows[self.keep]
        unique, self.position = np.unique(keys, return_inverse=True)
        self.indices = (unique % self.n).astype(np.int32)
        self.indptr = np.searchsorted(unique // self.n, np.arange(self.n + 1)).astype(np.int32)
        self.nnz = unique.size

    def matrix(self, values: np.ndarray, unit: np.ndarray) -> sp.csc_matrix:
        """`sum_e v_e A_e` on the kept degrees of freedom, `(n, n)` CSC."""
        entries = (np.asarray(values)[:, None] * np.asarray(unit).reshape(-1, 64)).ravel()[self.keep]
        data = np.bincount(self.position, weights=entries, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


@functools.lru_cache(maxsize=16)
def csc_pattern(mesh: QuadMesh, removed: tuple[int, ...]) -> CscPattern:
    """The (cached) [`CscPattern`][] of `mesh` without the degrees of freedom `removed`."""
    return CscPattern(mesh, tuple(sorted(int(d) for d in removed)))


def csc_matrices(mesh: QuadMesh, youngs, densities, unit_stiffness, unit_mass,
                 removed: tuple[int, ...] = ()) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """Host `K` and `M` as SciPy CSC matrices on the degrees of freedom not in `removed`.

    **Arguments:** NumPy arrays: `youngs`, `densities` `(n_elements,)`, `unit_stiffness`,
    `unit_mass` `(n_elements, 8, 8)` (an [`FEModel`][]'s fields).

    **Returns:** `(K, M)`, `scipy.sparse.csc_matrix` of shape `(n_kept, n_kept)`.
    """
    pattern = csc_pattern(mesh, tuple(removed))
    return pattern.matrix(youngs, unit_stiffness), pattern.matrix(densities, unit_mass)
