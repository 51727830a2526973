"""Q4 with incompatible bending modes and the Taylor–Beresford–Wilson correction (QM6)."""

import numpy as np

from .base import AbstractElement, bilinear, consistent_mass, gauss_points_2x2, jacobians, plane_stress, strain_matrix


class QM6(AbstractElement):
    """The bilinear quadrilateral enriched with two incompatible modes per displacement component.

    The displacement is `u = N u_e + P a` with the bilinear `N`, nodal values `u_e` and the
    internal modes `P = (1 - xi^2, 1 - eta^2)` of amplitudes `a` (four per element), which add the
    quadratic terms of pure bending that Q4 lacks (Wilson et al. 1973). Their strains are formed
    with the Jacobian at the element centre and scaled by `det J0 / det J`,

    `B_a(xi, eta) = det J0 / det J(xi, eta) * B[J0^-1 dP(xi, eta)]`,

    so that `sum_g B_a det J w_g = det J0 sum_g B[J0^-1 dP] w_g = 0` for any quadrilateral and a
    constant strain state leaves `a = 0`: the element passes the patch test on distorted meshes
    (Taylor, Beresford and Wilson 1976). The amplitudes are condensed out element by element,

    `K_e = K_uu - K_ua K_aa^-1 K_au`,  `K_xy = t sum_g B_x^T D B_y det J w_g` (2x2 Gauss),

    and the mass is the consistent mass of the nodal field (that of [`Q4`][]). On rectangles the
    element represents pure bending exactly; `K_e` scales with `E` as Q4's does, so SIMP scales
    the condensed matrix.

    !!! cite "References"
        E. L. Wilson, R. L. Taylor, W. P. Doherty, J. Ghaboussi, "Incompatible displacement
        models", in *Numerical and Computer Methods in Structural Mechanics*, Academic Press
        (1973) 43–57.

        R. L. Taylor, P. J. Beresford, E. L. Wilson, "A non-conforming element for stress
        analysis", Int. J. Numer. Methods Eng. 10 (1976) 1211–1219.
    """

    def matrices(self, xy: np.ndarray, poisson: float, thickness: float) -> tuple[np.ndarray, np.ndarray]:
        xy = np.asarray(xy, dtype=np.float64)
        d = plane_stress(poisson)
        m = xy.shape[0]
        _, dn0 = bilinear(0.0, 0.0)
        _, det0, inv0 = jacobians(dn0, xy)
        k_uu = np.zeros((m, 8, 8))
        k_ua = np.zeros((m, 8, 4))
        k_aa = np.zeros((m, 4, 4))
        for (xi, eta), w in gauss_points_2x2():
            _, dn = bilinear(xi, eta)
            _, det, inv = jacobians(dn, xy)
            b_u = strain_matrix(inv @ dn)
            dp = np.array([[-2.0 * xi, 0.0], [0.0, -2.0 * eta]])  # d(1 - xi^2, 1 - eta^2) / d(xi, eta)
            b_a = (det0 / det)[:, None, None] * strain_matrix(inv0 @ dp)
            weight = (w * thickness * det)[:, None, None]
            b_u_t, db_a = np.swapaxes(b_u, 1, 2), d @ b_a
            k_uu += weight * (b_u_t @ (d @ b_u))
            k_ua += weight * (b_u_t @ db_a)
            k_aa += weight * (np.swapaxes(b_a, 1, 2) @ db_a)
        k = k_uu - k_ua @ np.linalg.solve(k_aa, np.swapaxes(k_ua, 1, 2))
        k = 0.5 * (k + np.swapaxes(k, 1, 2))
        return k, consistent_mass(xy, thickness)
