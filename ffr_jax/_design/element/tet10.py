"""The isoparametric quadratic tetrahedron (Tet10)."""

from typing import ClassVar

import numpy as np

from .solid_base import (MIN_JACOBIAN_RATIO, AbstractSolidElement, _format_ids, check_poisson,
                         gradient_moments, isotropic_block, jacobian_determinants, jacobians, nodal_mass)

# Reference vertices (volume coordinates L1 = 1 - xi - eta - zeta, L2 = xi, L3 = eta, L4 = zeta) and
# the edges of the mid-side nodes 4..9 in the VTK/meshio order.
TET_VERTICES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TET_EDGES = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))
_D_VOLUME = np.array([[-1.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 1.0]])  # dL_i / dxi_k

# Smallest admissible shape quality 6 sqrt(2) V / l_max^3 (1 for the regular tetrahedron, 0 for a flat
# one). A sliver's stiffness matrix has a condition number growing like 1 / quality^2, so at 1e-3 an
# element costs six digits of the solve; meshers (gmsh's optimiser) keep their elements far above.
MIN_TET_QUALITY = 1e-3


def quadratic_tet(xi: float, eta: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """Quadratic shape functions `N` `(10,)` and natural derivatives `dN` `(3, 10)` at `(xi, eta, zeta)`.

    Vertices `N_i = L_i (2 L_i - 1)`, mid-side nodes `N_ab = 4 L_a L_b`.
    """
    l = np.array([1.0 - xi - eta - zeta, xi, eta, zeta])
    n = np.concatenate([l * (2 * l - 1), [4 * l[a] * l[b] for a, b in TET_EDGES]])
    dn = np.concatenate([_D_VOLUME * (4 * l - 1),
                         np.stack([4 * (l[b] * _D_VOLUME[:, a] + l[a] * _D_VOLUME[:, b]) for a, b in TET_EDGES], 1)],
                        axis=1)
    return n, dn


def gauss_points_4():
    """The 4-point rule of degree 2 on the reference tetrahedron (volume 1/6): `(point, weight)` pairs."""
    a, b = (5.0 + 3.0 * np.sqrt(5.0)) / 20.0, (5.0 - np.sqrt(5.0)) / 20.0
    points = [(b, b, b), (a, b, b), (b, a, b), (b, b, a)]
    return [(p, 1.0 / 24.0) for p in points]


def conical_product_points(n: int = 4):
    """A conical product rule (Stroud): Gauss–Legendre on the cube mapped to the tetrahedron.

    `xi = u`, `eta = (1 - u) v`, `zeta = (1 - u)(1 - v) w` with Jacobian `(1 - u)^2 (1 - v)`; `n`
    points per direction integrate every polynomial of total degree `2 n - 3` exactly (the `u`
    degree grows by 2, the `v` degree by 1). `n = 4`: degree 5, enough for the quartic
    `N^T N` of the consistent mass.
    """
    t, w = np.polynomial.legendre.leggauss(n)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    out = []
    for u, wu in zip(t, w):
        for v, wv in zip(t, w):
            for s, ws in zip(t, w):
                point = (u, (1 - u) * v, (1 - u) * (1 - v) * s)
                out.append((point, wu * wv * ws * (1 - u) ** 2 * (1 - v)))
    return out


class Tet10(AbstractSolidElement):
    """Isoparametric 10-node quadratic tetrahedron, isotropic linear elasticity.

    `K_e = sum_g B^T D B det J w_g` over the 4-point rule of degree 2 (exact for straight edges,
    where `B` is linear), `M_e = sum_g N^T N det J w_g` (consistent mass) over a 64-point conical
    product rule of degree 5 (exact for straight edges, where `N^T N` is quartic). The quadratic
    field represents pure bending exactly, so the element does not lock in bending; it is the
    element for meshes of CAD geometry (gmsh `Mesh.ElementOrder = 2`). Nodes in the VTK order:
    vertices 0..3 (0, 1, 2 counter-clockwise seen from 3), then the mid-side nodes of the edges
    `(0,1), (1,2), (2,0), (0,3), (1,3), (2,3)`.
    """

    n_nodes: ClassVar[int] = 10
    cell_type: ClassVar[str] = "tetra10"

    def jacobian_samples(self, xyz: np.ndarray) -> np.ndarray:
        points = list(TET_VERTICES) + [0.5 * (TET_VERTICES[a] + TET_VERTICES[b]) for a, b in TET_EDGES]
        points += [p for p, _ in gauss_points_4()] + [(0.25, 0.25, 0.25)]
        return np.stack([jacobian_determinants(quadratic_tet(*p)[1], xyz) for p in points], axis=1)

    def reordered(self) -> np.ndarray:
        return np.array([0, 2, 1, 3, 6, 5, 4, 7, 9, 8])

    def check(self, xyz: np.ndarray, min_ratio: float = MIN_JACOBIAN_RATIO, reorder_hint: str = "") -> None:
        """The Jacobian checks of `check_jacobians`, and slivers: shape quality
        `6 sqrt(2) V / l_max^3` of the vertex tetrahedron below `MIN_TET_QUALITY` (1e-3)."""
        super().check(xyz, min_ratio, reorder_hint)
        v = np.asarray(xyz, dtype=np.float64)[:, :4]
        volume = np.linalg.det(v[:, 1:] - v[:, :1]) / 6.0
        edges = np.stack([v[:, a] - v[:, b] for a, b in TET_EDGES[:3] + ((0, 3), (1, 3), (2, 3))], 1)
        l_max = np.sqrt(np.max(np.sum(edges**2, axis=-1), axis=1))
        quality = 6.0 * np.sqrt(2.0) * volume / l_max**3
        bad = np.flatnonzero(quality < MIN_TET_QUALITY)
        if bad.size:
            raise ValueError(f"Tet10 elements {_format_ids(bad)} are badly shaped slivers (shape quality "
                             f"{quality[bad].min():.3g} < {MIN_TET_QUALITY}, 1 for a regular tetrahedron); "
                             "remesh them.")

    def matrices(self, xyz: np.ndarray, poisson: float) -> tuple[np.ndarray, np.ndarray]:
        xyz = np.asarray(xyz, dtype=np.float64)
        poisson = check_poisson(poisson)
        self.check(xyz)
        moments = 0.0
        for point, w in gauss_points_4():
            _, dn = quadratic_tet(*point)
            det, inv = jacobians(dn, xyz)
            grad = np.swapaxes(inv @ dn, 1, 2)
            moments = moments + gradient_moments(grad, grad, w * det)
        k = isotropic_block(moments, poisson)  # sum_g B^T D B det J w_g
        return 0.5 * (k + np.swapaxes(k, 1, 2)), nodal_mass(conical_product_points(4), xyz, quadratic_tet)
