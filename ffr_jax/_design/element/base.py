"""The element interface: unit stiffness and consistent mass of a batch of plane quadrilaterals."""

import abc

import equinox as eqx
import numpy as np

from ..mesh import CORNERS, GAUSS_2


def plane_stress(poisson: float) -> np.ndarray:
    """Plane-stress elasticity matrix `D` for `E = 1`, strains `(eps_xx, eps_yy, gamma_xy)`, `(3, 3)`."""
    nu = poisson
    return np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)


def bilinear(xi: float, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear shape functions `N` `(4,)` and their natural derivatives `dN` `(2, 4)` at `(xi, eta)`."""
    n = 0.25 * (1 + CORNERS[:, 0] * xi) * (1 + CORNERS[:, 1] * eta)
    dn = 0.25 * np.stack([CORNERS[:, 0] * (1 + CORNERS[:, 1] * eta), CORNERS[:, 1] * (1 + CORNERS[:, 0] * xi)])
    return n, dn


def gauss_points_2x2():
    """The 2x2 Gauss rule: `((xi, eta), weight)` pairs, weights 1."""
    return [((xi, eta), 1.0) for xi in GAUSS_2 for eta in GAUSS_2]


def jacobians(dn: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jacobian of the bilinear map for each element at one point.

    **Arguments:** `dn` `(2, 4)` natural derivatives of the shape functions; `xy` `(m, 4, 2)` corners.

    **Returns:** `(J, det J, J^-1)`, `J[e, i, j] = d x_j / d xi_i`, shapes `(m, 2, 2)`, `(m,)`, `(m, 2, 2)`.
    """
    jac = dn @ xy
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    inv = np.stack([np.stack([jac[:, 1, 1], -jac[:, 0, 1]], -1), np.stack([-jac[:, 1, 0], jac[:, 0, 0]], -1)], 1)
    return jac, det, inv / det[:, None, None]


def strain_matrix(dxy: np.ndarray) -> np.ndarray:
    """Strain–displacement matrix `B` `(m, 3, 2k)` from Cartesian derivatives `dxy` `(m, 2, k)`,
    degrees of freedom `(u_x, u_y)` interleaved per function."""
    m, _, k = dxy.shape
    b = np.zeros((m, 3, 2 * k))
    b[:, 0, 0::2] = dxy[:, 0]
    b[:, 1, 1::2] = dxy[:, 1]
    b[:, 2, 0::2] = dxy[:, 1]
    b[:, 2, 1::2] = dxy[:, 0]
    return b


def consistent_mass(xy: np.ndarray, thickness: float) -> np.ndarray:
    """Consistent mass `M_e = t sum_g N^T N det J` for `rho = 1` (2x2 Gauss), `(m, 8, 8)`.

    2x2 Gauss integrates the mass of a parallelogram exactly (`N^T N det J` is then biquadratic).
    """
    m = np.zeros((xy.shape[0], 8, 8))
    for (xi, eta), w in gauss_points_2x2():
        n, dn = bilinear(xi, eta)
        _, det, _ = jacobians(dn, xy)
        nn = np.zeros((2, 8))
        nn[0, 0::2] = n
        nn[1, 1::2] = n
        m += (w * thickness * det)[:, None, None] * (nn.T @ nn)[None]
    return m


class AbstractElement(eqx.Module):
    """A plane-stress quadrilateral element: unit matrices of a batch of elements from their corners.

    Element matrices do not depend on the design: the stiffness is computed for `E = 1` and the
    mass for `rho = 1`, and SIMP scales them per element. Degrees of freedom are ordered
    `(u_x, u_y)` per node, nodes counter-clockwise.
    """

    @abc.abstractmethod
    def matrices(self, xy: np.ndarray, poisson: float, thickness: float) -> tuple[np.ndarray, np.ndarray]:
        """Unit stiffness and consistent mass of each element.

        **Arguments:**
        - `xy`: `(m, 4, 2)` corner coordinates, counter-clockwise.
        - `poisson`: Poisson ratio (plane stress); `thickness`: out-of-plane thickness.

        **Returns:** `(K_e, M_e)`, NumPy arrays `(m, 8, 8)` each.
        """
