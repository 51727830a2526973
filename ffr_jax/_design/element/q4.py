"""The isoparametric bilinear quadrilateral (Q4)."""

import numpy as np

from .base import AbstractElement, bilinear, consistent_mass, gauss_points_2x2, jacobians, plane_stress, strain_matrix


class Q4(AbstractElement):
    """Isoparametric 4-node bilinear quadrilateral, plane stress, 2x2 Gauss quadrature.

    `K_e = t sum_g B^T D B det J w_g` and `M_e = t sum_g N^T N det J w_g` (consistent mass) over
    the 2x2 Gauss points, for any convex quadrilateral (REFERENCE_CASE §1 for rectangles). It
    passes the patch test but locks in bending: a slender beam needs several elements per
    thickness-to-length ratio; [`QM6`][] does not lock.
    """

    def matrices(self, xy: np.ndarray, poisson: float, thickness: float) -> tuple[np.ndarray, np.ndarray]:
        xy = np.asarray(xy, dtype=np.float64)
        d = plane_stress(poisson)
        k = np.zeros((xy.shape[0], 8, 8))
        for (xi, eta), w in gauss_points_2x2():
            _, dn = bilinear(xi, eta)
            _, det, inv = jacobians(dn, xy)
            b = strain_matrix(inv @ dn)
            k += (w * thickness * det)[:, None, None] * (np.swapaxes(b, 1, 2) @ (d @ b))
        return k, consistent_mass(xy, thickness)
