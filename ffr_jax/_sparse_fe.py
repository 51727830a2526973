"""Sparse finite element stage: matrix-free global matrices and their SciPy counterparts.

On large meshes a dense `(n_dof, n_dof)` matrix does not fit (a 1000 x 100 rod has about
200,000 degrees of freedom: 320 GB dense). Every global matrix of the rod has the form

`A = sum_e v_e P_e^T A_e P_e`,

one `(8, 8)` unit element matrix `A_e` (stiffness for `E = 1`, mass for `rho = 1`) scaled per
element by `v_e` (Young's modulus or mass density). [`ElementOperator`][] keeps only `v` and
applies `A` by gathering element vectors, multiplying by `A_e` and scattering back: memory and
time linear in the number of elements, and differentiable with respect to both `v` and the
vector by ordinary JAX autodiff. The SciPy CSC matrix of the same `A` (for sparse factorisations
on the host) reuses one sparsity pattern per mesh, so assembling it costs one `bincount`.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, Float

from ._fe import RodMesh, assemble
from ._typing import ElementField


_KINDS = ("stiffness", "mass")


class ElementOperator(eqx.Module):
    """The global matrix `A = sum_e v_e P_e^T A_e P_e` of a rod, applied without forming it.

    - `mesh`: the rod mesh (static).
    - `values`: `(n_elements,)` the per-element scale `v_e` (Young's moduli for `"stiffness"`,
      mass densities for `"mass"`).
    - `kind`: `"stiffness"` or `"mass"` (static): which unit element matrix `A_e`.

    `A @ v` works for `v` of shape `(n_dof,)` or `(n_dof, k)`, so the operator stands in for a
    dense matrix wherever only products are needed (e.g. [`flexible_body_data`][]).
    """

    mesh: RodMesh
    values: Float[Array, " n_elements"]
    kind: str = eqx.field(static=True)

    def __check_init__(self):
        if self.kind not in _KINDS:
            raise ValueError(f"ElementOperator kind must be one of {_KINDS}, got {self.kind!r}.")

    @property
    def shape(self) -> tuple[int, int]:
        return (self.mesh.n_dof, self.mesh.n_dof)

    @property
    def element_matrix(self) -> np.ndarray:
        """The unit element matrix `A_e`, `(8, 8)`."""
        return self.mesh.element_matrices()[_KINDS.index(self.kind)]

    def __matmul__(self, v):
        v = jnp.asarray(v)
        if v.ndim not in (1, 2) or v.shape[0] != self.mesh.n_dof:
            raise ValueError(f"ElementOperator of shape {self.shape} cannot multiply an array of shape {v.shape}.")
        dofs = element_dofs(self.mesh)
        columns = v.reshape(self.mesh.n_dof, -1)
        local = columns[dofs]  # (n_elements, 8, k)
        local = self.values[:, None, None] * jnp.einsum("ab,ebk->eak", jnp.asarray(self.element_matrix), local)
        out = jax.ops.segment_sum(local.reshape(-1, columns.shape[1]), dofs.ravel(), num_segments=self.mesh.n_dof)
        return out.reshape(v.shape)

    def todense(self) -> Float[Array, "n_dof n_dof"]:
        """The dense matrix (small meshes and tests only)."""
        return assemble(self.mesh, self.values, self.element_matrix)


def sparse_stiffness_matrix(mesh: RodMesh, youngs: ElementField) -> ElementOperator:
    """Matrix-free global stiffness `K = sum_e E_e K_e` (the sparse counterpart of `stiffness_matrix`)."""
    return ElementOperator(mesh, youngs, "stiffness")


def sparse_mass_matrix(mesh: RodMesh, densities: ElementField) -> ElementOperator:
    """Matrix-free consistent mass `M = sum_e rho_e M_e` (the sparse counterpart of `mass_matrix`)."""
    return ElementOperator(mesh, densities, "mass")


def _mesh_key(mesh: RodMesh) -> tuple:
    return (mesh.nx, mesh.ny, mesh.length, mesh.height, mesh.thickness, mesh.poisson)


@functools.cache
def _element_dofs(key: tuple) -> np.ndarray:
    dofs = RodMesh(*key).element_dofs()
    dofs.flags.writeable = False
    return dofs


def element_dofs(mesh: RodMesh) -> np.ndarray:
    """`mesh.element_dofs()`, computed once per mesh (read-only)."""
    return _element_dofs(_mesh_key(mesh))


class _Pattern:
    """CSC sparsity pattern of a rod matrix restricted to the free degrees of freedom.

    `position[k]` is where entry `k` of the flat element-matrix list (`(n_elements, 8, 8)`,
    entries touching a fixed degree of freedom removed by `keep`) lands in the CSC data array.
    """

    def __init__(self, mesh: RodMesh, fixed_dofs: tuple[int, ...]):
        n_dof = mesh.n_dof
        self.free = np.setdiff1d(np.arange(n_dof), np.asarray(fixed_dofs, dtype=int))
        self.n = self.free.size
        renumber = np.full(n_dof, -1)
        renumber[self.free] = np.arange(self.n)
        local = renumber[element_dofs(mesh)]
        rows = np.repeat(local, 8, axis=1).ravel()
        cols = np.tile(local, (1, 8)).ravel()
        self.keep = (rows >= 0) & (cols >= 0)
        keys = cols[self.keep].astype(np.int64) * self.n + rows[self.keep]
        unique, self.position = np.unique(keys, return_inverse=True)
        self.indices = (unique % self.n).astype(np.int32)
        self.indptr = np.searchsorted(unique // self.n, np.arange(self.n + 1)).astype(np.int32)
        self.nnz = unique.size

    def matrix(self, values: np.ndarray, element_matrix: np.ndarray) -> sp.csc_matrix:
        entries = (values[:, None] * element_matrix.ravel()[None, :]).ravel()[self.keep]
        data = np.bincount(self.position, weights=entries, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


@functools.cache
def _pattern(key: tuple, fixed_dofs: tuple[int, ...]) -> _Pattern:
    return _Pattern(RodMesh(*key), fixed_dofs)


def free_pattern(mesh: RodMesh, fixed_dofs: tuple[int, ...]) -> _Pattern:
    """The (cached) CSC pattern of the rod's matrices on the degrees of freedom not in `fixed_dofs`."""
    return _pattern(_mesh_key(mesh), tuple(int(d) for d in fixed_dofs))


def scipy_matrices(mesh: RodMesh, youngs, densities, fixed_dofs: tuple[int, ...]) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """Host (NumPy/SciPy) `K_ff` and `M_ff` as CSC matrices on the free degrees of freedom.

    **Arguments:**
    - `mesh`: the rod mesh; `youngs`, `densities`: `(n_elements,)` NumPy arrays.
    - `fixed_dofs`: degrees of freedom removed (rows and columns).

    **Returns:** `(K_ff, M_ff)`, `scipy.sparse.csc_matrix` of shape `(n_free, n_free)`.
    """
    pattern = free_pattern(mesh, fixed_dofs)
    k_e, m_e = mesh.element_matrices()
    return pattern.matrix(np.asarray(youngs), k_e), pattern.matrix(np.asarray(densities), m_e)


# Meshes with more degrees of freedom than this take the sparse path under `fe_path="auto"`.
# Measured on the reference rod (1,414 dofs, 6 modes, 2-core CPU, one thread): forward + VJP of
# the FE stage 0.30 s sparse vs 17-26 s dense (full eigen-solution and its cubic derivative),
# with psi equal to 8e-12 and the gradient of a mode-invariant functional to 7e-13 relative.
# The dense path stays for small meshes, where it is quick and also differentiable in forward
# mode (`jax.jvp`), which the sparse path's reverse-mode eigen-derivative is not.
SPARSE_MIN_DOF = 1000

FE_PATHS = ("auto", "dense", "sparse")


def resolve_fe_path(fe_path: str, mesh: RodMesh) -> str:
    """`"dense"` or `"sparse"`: the FE path a case with option `fe_path` takes on `mesh`.

    `"auto"` picks `"sparse"` when `mesh.n_dof > SPARSE_MIN_DOF` (1,000; the reference rod has
    1,414), else `"dense"`.
    """
    if fe_path not in FE_PATHS:
        raise ValueError(f"fe_path must be one of {FE_PATHS}, got {fe_path!r}.")
    if fe_path == "auto":
        return "sparse" if mesh.n_dof > SPARSE_MIN_DOF else "dense"
    return fe_path
