"""Plane-stress finite element model of a rectangular rod: Q4 elements, structured mesh, assembly.

Node `(i, j)` (column `i = 0..nx`, row `j = 0..ny`) sits at `(i L / nx, -h/2 + j h / ny)` and has
global index `i (ny + 1) + j` (column-major, which keeps the bandwidth at `2 (ny + 2)`); its
degrees of freedom are `2 n` (x) and `2 n + 1` (y). Element `(i, j)` has the nodes
`(i, j), (i+1, j), (i+1, j+1), (i, j+1)` (counter-clockwise) and the flat index `j nx + i`.
"""

import functools

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._typing import ElementField


_GAUSS = np.array([-1.0, 1.0]) / np.sqrt(3.0)
_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def _shape_functions(xi: float, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear shape functions `N` (4,) and their natural derivatives `dN` (2, 4) at `(xi, eta)`."""
    n = 0.25 * (1 + _CORNERS[:, 0] * xi) * (1 + _CORNERS[:, 1] * eta)
    dn = 0.25 * np.stack(
        [_CORNERS[:, 0] * (1 + _CORNERS[:, 1] * eta), _CORNERS[:, 1] * (1 + _CORNERS[:, 0] * xi)]
    )
    return n, dn


@functools.cache
def q4_element_matrices(dx: float, dy: float, nu: float, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness (for `E = 1`) and consistent mass (for `rho = 1`) of one rectangular Q4 element.

    Isoparametric bilinear element of size `dx x dy`, plane stress,
    `K_e = t sum_g B^T D B det(J) w_g` and `M_e = t sum_g N^T N det(J) w_g` with 2x2 Gauss
    quadrature (exact for the mass matrix of a rectangle). Degrees of freedom are ordered
    `(u_x, u_y)` per node, nodes counter-clockwise from the lower left corner.

    **Returns:** `(K_e, M_e)`, each `(8, 8)` NumPy arrays (element matrices do not depend on the
    design; SIMP scales them).
    """
    d = np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)
    jac = np.diag([dx / 2.0, dy / 2.0])
    det_j = np.linalg.det(jac)
    inv_j = np.linalg.inv(jac)
    k = np.zeros((8, 8))
    m = np.zeros((8, 8))
    for xi in _GAUSS:
        for eta in _GAUSS:
            n, dn = _shape_functions(xi, eta)
            dxy = inv_j @ dn  # (2, 4): dN/dx, dN/dy
            b = np.zeros((3, 8))
            b[0, 0::2] = dxy[0]
            b[1, 1::2] = dxy[1]
            b[2, 0::2] = dxy[1]
            b[2, 1::2] = dxy[0]
            nn = np.zeros((2, 8))
            nn[0, 0::2] = n
            nn[1, 1::2] = n
            k += b.T @ d @ b * det_j * thickness
            m += nn.T @ nn * det_j * thickness
    return k, m


class RodMesh(eqx.Module):
    """Structured `nx x ny` mesh of Q4 elements over `[0, L] x [-h/2, h/2]` (REFERENCE_CASE §1).

    All fields are static: a mesh is configuration, not data. Index arrays are built once, in
    NumPy, at construction.
    """

    nx: int = eqx.field(static=True)
    ny: int = eqx.field(static=True)
    length: float = eqx.field(static=True)
    height: float = eqx.field(static=True)
    thickness: float = eqx.field(static=True)
    poisson: float = eqx.field(static=True)

    def __init__(self, nx: int, ny: int, length: float = 1.0, height: float = 0.06, thickness: float = 0.01,
                 poisson: float = 0.3):
        if not (isinstance(nx, int) and isinstance(ny, int)):
            raise ValueError(f"nx and ny must be Python ints, got {nx!r}, {ny!r}.")
        if nx < 4:
            raise ValueError(f"nx must be at least 4 (two solid interface columns and design columns), got {nx}.")
        if ny < 2 or ny % 2:
            raise ValueError(
                f"ny must be even and at least 2 so that the joint points A and B are mesh nodes at "
                f"mid-height, got ny={ny}."
            )
        if min(length, height, thickness) <= 0:
            raise ValueError("length, height and thickness must be positive.")
        if not 0.0 <= poisson < 0.5:
            raise ValueError(f"Poisson ratio must lie in [0, 0.5), got {poisson}.")
        self.nx, self.ny = nx, ny
        self.length, self.height, self.thickness = float(length), float(height), float(thickness)
        self.poisson = float(poisson)

    @property
    def n_nodes(self) -> int:
        return (self.nx + 1) * (self.ny + 1)

    @property
    def n_dof(self) -> int:
        return 2 * self.n_nodes

    @property
    def n_elements(self) -> int:
        return self.nx * self.ny

    @property
    def dx(self) -> float:
        return self.length / self.nx

    @property
    def dy(self) -> float:
        return self.height / self.ny

    def node(self, i, j):
        """Global index of node `(i, j)` (integers or integer arrays)."""
        return i * (self.ny + 1) + j

    @property
    def node_a(self) -> int:
        """Joint point A: left edge, mid-height (body coordinates `(0, 0)`)."""
        return self.node(0, self.ny // 2)

    @property
    def node_b(self) -> int:
        """Joint point B: right edge, mid-height (body coordinates `(L, 0)`)."""
        return self.node(self.nx, self.ny // 2)

    def node_coordinates(self) -> np.ndarray:
        """Undeformed node coordinates `(n_nodes, 2)` in the body frame (origin at A)."""
        i, j = np.meshgrid(np.arange(self.nx + 1), np.arange(self.ny + 1), indexing="ij")
        xy = np.stack([i * self.dx, -0.5 * self.height + j * self.dy], axis=-1)
        return xy.reshape(-1, 2)

    def element_centres(self) -> np.ndarray:
        """Element centres `(n_elements, 2)` in flat element order `j nx + i`."""
        j, i = np.meshgrid(np.arange(self.ny), np.arange(self.nx), indexing="ij")
        return np.stack([(i + 0.5) * self.dx, -0.5 * self.height + (j + 0.5) * self.dy], -1).reshape(-1, 2)

    def element_dofs(self) -> np.ndarray:
        """Global degrees of freedom `(n_elements, 8)` of each element, flat order `j nx + i`."""
        j, i = np.meshgrid(np.arange(self.ny), np.arange(self.nx), indexing="ij")
        i, j = i.ravel(), j.ravel()
        nodes = np.stack([self.node(i, j), self.node(i + 1, j), self.node(i + 1, j + 1), self.node(i, j + 1)], -1)
        return np.stack([2 * nodes, 2 * nodes + 1], -1).reshape(-1, 8)

    def element_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit-modulus stiffness and unit-density mass of one element, `(8, 8)` each."""
        return q4_element_matrices(self.dx, self.dy, self.poisson, self.thickness)


def assemble(mesh: RodMesh, element_values: ElementField, element_matrix: np.ndarray) -> Float[Array, "n_dof n_dof"]:
    """Dense assembly `sum_e v_e P_e^T A_e P_e` of one element matrix scaled per element.

    **Arguments:**
    - `mesh`: the mesh (static).
    - `element_values`: `(n_elements,)` scale of each element (Young's modulus or density).
    - `element_matrix`: `(8, 8)` element matrix for unit scale.

    **Returns:** `(n_dof, n_dof)` symmetric matrix.
    """
    dofs = mesh.element_dofs()
    rows = np.repeat(dofs, 8, axis=1).ravel()
    cols = np.tile(dofs, (1, 8)).ravel()
    vals = (element_values[:, None] * jnp.asarray(element_matrix).ravel()[None, :]).ravel()
    return jnp.zeros((mesh.n_dof, mesh.n_dof)).at[rows, cols].add(vals)


def stiffness_matrix(mesh: RodMesh, youngs: ElementField) -> Float[Array, "n_dof n_dof"]:
    """Global stiffness `K = sum_e E_e K_e` for element Young's moduli `youngs` `(n_elements,)`."""
    return assemble(mesh, youngs, mesh.element_matrices()[0])


def mass_matrix(mesh: RodMesh, densities: ElementField) -> Float[Array, "n_dof n_dof"]:
    """Global consistent mass `M = sum_e rho_e M_e` for element mass densities `(n_elements,)`."""
    return assemble(mesh, densities, mesh.element_matrices()[1])
