"""H8 with nine incompatible modes and Taylor's correction (H11, the 3D counterpart of QM6)."""

from typing import ClassVar

import numpy as np

from .h8 import check_hex_corners, gauss_points_2x2x2, hex_jacobian_samples, trilinear
from .solid_base import (MIN_JACOBIAN_RATIO, AbstractSolidElement, check_poisson, gradient_moments, isotropic_block,
                         jacobians, nodal_mass)


class H11(AbstractSolidElement):
    """The trilinear hexahedron enriched with three incompatible modes per displacement component.

    The displacement is `u = N u_e + P a` with the trilinear `N`, nodal values `u_e` and the
    internal modes `P = (1 - xi^2, 1 - eta^2, 1 - zeta^2)` of amplitudes `a` (nine per element),
    which add the quadratic terms of pure bending that [`H8`][] lacks (Wilson et al. 1973; the
    element is often called H11 for its eleven functions per component). Their strains are formed
    with the Jacobian at the element centre and scaled by `det J0 / det J`,

    `B_a(xi, eta, zeta) = det J0 / det J * B[J0^-1 dP]`,

    so that `sum_g B_a det J w_g = det J0 sum_g B[J0^-1 dP(g)] w_g = 0` on any hexahedron (the
    2x2x2 Gauss points are symmetric and `dP` is odd in each coordinate): a constant strain
    leaves `a = 0` and the element passes the patch test on distorted meshes (Taylor, Beresford
    and Wilson 1976). The amplitudes are condensed out element by element,

    `K_e = K_uu - K_ua K_aa^-1 K_au`,  `K_xy = sum_g B_x^T D B_y det J w_g` (2x2x2 Gauss),

    and the mass is the consistent mass of the nodal field (that of [`H8`][]). On rectangular boxes
    it represents pure bending exactly.

    !!! cite "References"
        E. L. Wilson, R. L. Taylor, W. P. Doherty, J. Ghaboussi, "Incompatible displacement
        models", in *Numerical and Computer Methods in Structural Mechanics*, Academic Press
        (1973) 43–57.

        R. L. Taylor, P. J. Beresford, E. L. Wilson, "A non-conforming element for stress
        analysis", Int. J. Numer. Methods Eng. 10 (1976) 1211–1219.
    """

    n_nodes: ClassVar[int] = 8
    cell_type: ClassVar[str] = "hexahedron"

    def jacobian_samples(self, xyz: np.ndarray) -> np.ndarray:
        return hex_jacobian_samples(xyz)

    def reordered(self) -> np.ndarray:
        return np.array([4, 5, 6, 7, 0, 1, 2, 3])

    def check(self, xyz, min_ratio=MIN_JACOBIAN_RATIO, reorder_hint=""):
        """The checks of [`H8`][]."""
        super().check(xyz, min_ratio, reorder_hint)
        check_hex_corners(type(self).__name__, np.asarray(xyz, dtype=np.float64))

    def matrices(self, xyz: np.ndarray, poisson: float) -> tuple[np.ndarray, np.ndarray]:
        xyz = np.asarray(xyz, dtype=np.float64)
        poisson = check_poisson(poisson)
        self.check(xyz)
        det0, inv0 = jacobians(trilinear(0.0, 0.0, 0.0)[1], xyz)
        a_uu = a_ua = a_aa = 0.0
        for (xi, eta, zeta), w in gauss_points_2x2x2():
            _, dn = trilinear(xi, eta, zeta)
            det, inv = jacobians(dn, xyz)
            grad_u = np.swapaxes(inv @ dn, 1, 2)
            dp = np.diag([-2.0 * xi, -2.0 * eta, -2.0 * zeta])  # d(1 - xi^2, ...) / d(xi, eta, zeta)
            grad_a = (det0 / det)[:, None, None] * np.swapaxes(inv0 @ dp, 1, 2)  # B_a's gradients
            weight = w * det
            a_uu = a_uu + gradient_moments(grad_u, grad_u, weight)
            a_ua = a_ua + gradient_moments(grad_u, grad_a, weight)
            a_aa = a_aa + gradient_moments(grad_a, grad_a, weight)
        k_uu, k_ua, k_aa = (isotropic_block(a, poisson) for a in (a_uu, a_ua, a_aa))
        k = k_uu - k_ua @ np.linalg.solve(k_aa, np.swapaxes(k_ua, 1, 2))
        return 0.5 * (k + np.swapaxes(k, 1, 2)), nodal_mass(gauss_points_2x2x2(), xyz, trilinear)
