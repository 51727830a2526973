"""The half MBB beam of top88: static compliance of a Q4 plane-stress mesh, with its exact gradient."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from .._design.domain import DesignDomain
from .._design.element.q4 import Q4
from .._design.geometry import rod_domain


class MBBBeam:
    """Minimum compliance of the half MBB beam (Sigmund 2001; Andreassen et al. 2011, "top88").

    A `nelx x nely` grid of unit square Q4 plane-stress elements (`E0 = 1`, `nu = 0.3`, thickness
    1; the element stiffness is the package's [`Q4`][] element, equal to top88's `KE`).
    The left edge is a symmetry line (`u_x = 0`), the lower right corner sits on a roller
    (`u_y = 0`), and a unit load pulls the upper left corner down. With the modified SIMP law
    `E_e = E_min + x_e^p (E0 - E_min)` of the physical densities, the compliance and its gradient
    are (the problem is self-adjoint)

        c(x) = F^T U,   K(x) U = F,   dc/dx_e = -p x_e^(p-1) (E0 - E_min) u_e^T K_e u_e.

    The global system is assembled and solved with SciPy (sparse LU), outside JAX;
    [`MBBBeam.value_and_grad`][] wraps it in `jax.pure_callback` so that it runs inside the
    jit-compiled step of the optimisation loop.

    The element of row `j` (from the bottom) and column `i` is entry `j nelx + i` of the density
    vector, the order of the rod's design domain on a `(nelx + 2) x nely` mesh of unit elements (its
    interface columns are not design variables), so the package's [`DensityFilter`][] on
    [`MBBBeam.design`][] is top88's filter on this grid.

    **Arguments:**
    - `nelx`, `nely`: elements along and across the beam (60 x 20 in top88).
    - `penal`: the SIMP exponent `p`; `e_min`: the void stiffness; `nu`: Poisson's ratio.

    !!! cite "References"
        E. Andreassen, A. Clausen, M. Schevenels, B. S. Lazarov, O. Sigmund, "Efficient topology
        optimization in MATLAB using 88 lines of code", Struct. Multidiscip. Optim. 43 (2011) 1–16.
        O. Sigmund, "A 99 line topology optimization code written in Matlab", Struct.
        Multidiscip. Optim. 21 (2001) 120–127.
    """

    def __init__(self, nelx: int = 60, nely: int = 20, *, penal: float = 3.0, e_min: float = 1e-9, nu: float = 0.3):
        if nelx < 2 or nely < 2 or nely % 2:
            raise ValueError(f"The MBB grid needs nelx >= 2 and an even nely >= 2, got {nelx} x {nely}.")
        self.nelx, self.nely, self.penal, self.e_min = int(nelx), int(nely), float(penal), float(e_min)
        unit_square = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
        self.ke = Q4().matrices(unit_square, float(nu), 1.0)[0][0]
        j, i = np.meshgrid(np.arange(nely), np.arange(nelx), indexing="ij")
        i, j = i.ravel(), j.ravel()
        nodes = np.stack([self.node(i, j), self.node(i + 1, j), self.node(i + 1, j + 1), self.node(i, j + 1)], -1)
        self.edof = np.stack([2 * nodes, 2 * nodes + 1], -1).reshape(-1, 8)
        self.n_dof = 2 * (nelx + 1) * (nely + 1)
        fixed = np.union1d(2 * self.node(0, np.arange(nely + 1)), [2 * self.node(nelx, 0) + 1])
        self.free = np.setdiff1d(np.arange(self.n_dof), fixed)
        self.force = np.zeros(self.n_dof)
        self.force[2 * self.node(0, nely) + 1] = -1.0
        self.rows = np.repeat(self.edof, 8, axis=1).ravel()
        self.cols = np.tile(self.edof, (1, 8)).ravel()

    def node(self, i, j):
        """Node index of grid point `(i, j)` (column `i`, row `j` from the bottom)."""
        return i * (self.nely + 1) + j

    @functools.cached_property
    def design(self) -> DesignDomain:
        """A [`DesignDomain`][] whose design vector has this grid's element order and unit element size
        (for [`DensityFilter`][]; its mesh has one extra solid column on each side)."""
        return rod_domain(self.nelx + 2, self.nely, float(self.nelx + 2), float(self.nely))

    def displacements(self, x_phys) -> np.ndarray:
        """`U` `(n_dof,)` of the physical densities `(nelx nely,)`."""
        x_phys = np.asarray(x_phys, dtype=float)
        youngs = self.e_min + x_phys**self.penal * (1.0 - self.e_min)
        values = (youngs[:, None, None] * self.ke[None]).ravel()
        k = scipy.sparse.coo_matrix((values, (self.rows, self.cols)), shape=(self.n_dof, self.n_dof)).tocsc()
        free = self.free
        u = np.zeros(self.n_dof)
        u[free] = scipy.sparse.linalg.spsolve(k[free][:, free], self.force[free])
        return u

    def compliance_and_grad(self, x_phys) -> tuple[float, np.ndarray]:
        """`(c, dc/dx_phys)` in NumPy."""
        x_phys = np.asarray(x_phys, dtype=float)
        u = self.displacements(x_phys)
        ue = u[self.edof]
        energy = np.einsum("ei,ij,ej->e", ue, self.ke, ue)
        c = float(self.force @ u)
        grad = -self.penal * x_phys ** (self.penal - 1.0) * (1.0 - self.e_min) * energy
        return c, grad

    def value_and_grad(self, x_phys):
        """`(c, dc/dx_phys)` as JAX arrays, usable inside `jax.jit` (through `jax.pure_callback`)."""
        x_phys = jnp.asarray(x_phys)
        shapes = (jax.ShapeDtypeStruct((), x_phys.dtype), jax.ShapeDtypeStruct(x_phys.shape, x_phys.dtype))

        def host(x):
            c, grad = self.compliance_and_grad(x)
            return np.asarray(c, dtype=x.dtype), grad.astype(x.dtype)

        return jax.pure_callback(host, shapes, x_phys)
