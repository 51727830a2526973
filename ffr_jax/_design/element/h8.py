"""The isoparametric trilinear hexahedron (H8)."""

from typing import ClassVar

import numpy as np

from .solid_base import (DEGENERATE_RATIO, MIN_JACOBIAN_RATIO, AbstractSolidElement, _format_ids, check_poisson,
                         gradient_moments, isotropic_block, jacobian_determinants, jacobians,
                         nodal_mass)

# Corners of the reference cube in the VTK/meshio order: the face zeta = -1 counter-clockwise seen
# from +zeta, then the face zeta = +1 above it.
HEX_CORNERS = np.array([[-1.0, -1.0, -1.0], [1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [-1.0, 1.0, -1.0],
                        [-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]])
GAUSS_2 = np.array([-1.0, 1.0]) / np.sqrt(3.0)


def trilinear(xi: float, eta: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """Trilinear shape functions `N` `(8,)` and natural derivatives `dN` `(3, 8)` at `(xi, eta, zeta)`."""
    c = HEX_CORNERS
    fx, fy, fz = 1 + c[:, 0] * xi, 1 + c[:, 1] * eta, 1 + c[:, 2] * zeta
    n = fx * fy * fz / 8.0
    dn = np.stack([c[:, 0] * fy * fz, c[:, 1] * fx * fz, c[:, 2] * fx * fy]) / 8.0
    return n, dn


def gauss_points_2x2x2():
    """The 2x2x2 Gauss rule: `((xi, eta, zeta), weight)` pairs, weights 1."""
    return [((a, b, c), 1.0) for a in GAUSS_2 for b in GAUSS_2 for c in GAUSS_2]


def hex_jacobian_samples(xyz: np.ndarray) -> np.ndarray:
    """`det J` of the trilinear map at the 8 Gauss points and the centre, `(m, 9)`.

    Checked where the element is integrated: the corner Jacobians of acceptable distorted
    hexahedra may be slightly negative (the MacNeal–Harder 3D patch has one at -0.05 of the
    largest), and the element matrices only see `det J` at the Gauss points (and at the centre, H11).
    """
    points = [p for p, _ in gauss_points_2x2x2()] + [(0.0, 0.0, 0.0)]
    return np.stack([jacobian_determinants(trilinear(*p)[1], xyz) for p in points], axis=1)


def check_hex_corners(name: str, xyz: np.ndarray) -> None:
    """Refuse hexahedra with a vanishing corner Jacobian: coincident corners or collapsed edges
    (a wedge or pyramid written as a hexahedron), which the Gauss-point check lets through."""
    det = np.stack([jacobian_determinants(trilinear(*c)[1], xyz) for c in HEX_CORNERS], axis=1)
    size = np.sqrt(np.max(np.sum((xyz[:, :, None] - xyz[:, None]) ** 2, axis=-1), axis=(1, 2)))
    bad = np.flatnonzero(np.any(np.abs(det) <= DEGENERATE_RATIO * size[:, None] ** 3, axis=1))
    if bad.size:
        raise ValueError(f"{name} elements {_format_ids(bad)} are degenerate (a corner Jacobian vanishes: coincident "
                         "corners or collapsed edges, e.g. a wedge written as a hexahedron); remesh them.")


class H8(AbstractSolidElement):
    """Isoparametric 8-node trilinear hexahedron, isotropic linear elasticity, 2x2x2 Gauss quadrature.

    `K_e = sum_g B^T D B det J w_g` and `M_e = sum_g N^T N det J w_g` (consistent mass, exact on
    parallelepipeds where `N^T N det J` is at most quadratic in each natural coordinate), for
    `E = 1`, `rho = 1`. The counterpart of [`Q4`][]: it passes the patch test but locks in
    bending (parasitic shear), so a slender part needs several elements per thickness-to-length
    ratio; [`H11`][] does not lock. Nodes in the VTK order (`HEX_CORNERS`).
    """

    n_nodes: ClassVar[int] = 8
    cell_type: ClassVar[str] = "hexahedron"

    def jacobian_samples(self, xyz: np.ndarray) -> np.ndarray:
        return hex_jacobian_samples(xyz)

    def reordered(self) -> np.ndarray:
        return np.array([4, 5, 6, 7, 0, 1, 2, 3])

    def check(self, xyz, min_ratio=MIN_JACOBIAN_RATIO, reorder_hint=""):
        """The Jacobian checks of `check_jacobians` at the Gauss points and the centre, and no vanishing
        corner Jacobian."""
        super().check(xyz, min_ratio, reorder_hint)
        check_hex_corners(type(self).__name__, np.asarray(xyz, dtype=np.float64))

    def matrices(self, xyz: np.ndarray, poisson: float) -> tuple[np.ndarray, np.ndarray]:
        xyz = np.asarray(xyz, dtype=np.float64)
        poisson = check_poisson(poisson)
        self.check(xyz)
        moments = 0.0
        for point, w in gauss_points_2x2x2():
            _, dn = trilinear(*point)
            det, inv = jacobians(dn, xyz)
            grad = np.swapaxes(inv @ dn, 1, 2)
            moments = moments + gradient_moments(grad, grad, w * det)
        k = isotropic_block(moments, poisson)  # sum_g B^T D B det J w_g
        return 0.5 * (k + np.swapaxes(k, 1, 2)), nodal_mass(gauss_points_2x2x2(), xyz, trilinear)
