"""The solid element interface: unit stiffness and consistent mass of a batch of 3D elements.

Shared pieces of the solid elements: isotropic elasticity `D`, the strain–displacement matrix,
Jacobians of an isoparametric map, and the shape checks that refuse inverted, degenerate and
badly shaped elements with a message naming the element type and the element indices.
"""

import abc

import equinox as eqx
import numpy as np

# Smallest admissible ratio min det J / max det J over an element's sample points (a ratio of 20:1,
# the limit common FE codes warn at, as for the planar QuadMesh); below it an element is refused as
# badly shaped.
MIN_JACOBIAN_RATIO = 0.05
# A det J below this fraction of the element's size cubed counts as zero (degenerate element): it is
# round-off of the coordinates (a few eps), a thousand times above.
DEGENERATE_RATIO = 1e-12


def isotropic(poisson: float) -> np.ndarray:
    """3D isotropic elasticity matrix `D` for `E = 1`, `(6, 6)`.

    Strains in Voigt order `(eps_xx, eps_yy, eps_zz, gamma_yz, gamma_xz, gamma_xy)`;
    `D = 1 / ((1 + nu)(1 - 2 nu)) [[1 - nu, nu, nu], ...]` on the normal block and
    `G = 1 / (2 (1 + nu))` on the shear diagonal.
    """
    nu = poisson
    d = np.zeros((6, 6))
    d[:3, :3] = nu
    d[np.arange(3), np.arange(3)] = 1.0 - nu
    d[:3, :3] /= (1.0 + nu) * (1.0 - 2.0 * nu)
    d[np.arange(3, 6), np.arange(3, 6)] = 0.5 / (1.0 + nu)
    return d


def strain_matrix(dxyz: np.ndarray) -> np.ndarray:
    """Strain–displacement matrix `B` `(m, 6, 3k)` from Cartesian derivatives `dxyz` `(m, 3, k)`.

    Degrees of freedom `(u_x, u_y, u_z)` interleaved per function; strains in the Voigt order of
    `isotropic`.
    """
    m, _, k = dxyz.shape
    b = np.zeros((m, 6, 3 * k))
    dx, dy, dz = dxyz[:, 0], dxyz[:, 1], dxyz[:, 2]
    b[:, 0, 0::3], b[:, 1, 1::3], b[:, 2, 2::3] = dx, dy, dz
    b[:, 3, 1::3], b[:, 3, 2::3] = dz, dy
    b[:, 4, 0::3], b[:, 4, 2::3] = dz, dx
    b[:, 5, 0::3], b[:, 5, 1::3] = dy, dx
    return b


def gradient_moments(grad_a: np.ndarray, grad_b: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """`w g_a,i g_b,j` of one quadrature point, `(m, k_a, 3, k_b, 3)`: summed over the points, the input of
    [`isotropic_block`][]. `grad_a` `(m, k_a, 3)`, `grad_b` `(m, k_b, 3)` Cartesian gradients; `weight` `(m,)`."""
    return (grad_a * weight[:, None, None])[:, :, :, None, None] * grad_b[:, None, None, :, :]


def isotropic_block(moments: np.ndarray, poisson: float) -> np.ndarray:
    """`sum_g B_a^T D B_b det J w_g` from the summed [`gradient_moments`][] `A`, `(m, 3 k_a, 3 k_b)`.

    For the isotropic `D` of [`isotropic`][] (`E = 1`: Lame constants `lambda = nu / ((1 + nu)(1 - 2 nu))`,
    `mu = 1 / (2 (1 + nu))`) the block of functions `a`, `b` and components `i`, `j` is

    `lambda A_aibj + mu A_ajbi + mu delta_ij sum_k A_akbk`,  `A_aibj = sum_g w_g g_a,i g_b,j`,

    the same numbers as `B^T D B` with the strain matrix of [`strain_matrix`][], without its zeros, and
    linear in `A`, so the quadrature sum is taken once on `A`.
    """
    lam = poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
    mu = 0.5 / (1.0 + poisson)
    block = lam * moments + mu * moments.transpose(0, 1, 4, 3, 2)
    dot = mu * np.einsum("makbk->mab", moments)
    for i in range(3):
        block[:, :, i, :, i] += dot
    m, ka, _, kb, _ = block.shape
    return block.reshape(m, 3 * ka, 3 * kb)


def jacobians(dn: np.ndarray, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian determinant and inverse of an isoparametric map at one point, for each element.

    **Arguments:** `dn` `(3, n)` natural derivatives of the shape functions; `xyz` `(m, n, 3)` nodes.

    **Returns:** `(det J, J^-1)`, `J[e, i, j] = d x_j / d xi_i`, shapes `(m,)` and `(m, 3, 3)`.
    """
    jac = dn @ xyz
    return np.linalg.det(jac), np.linalg.inv(jac)


def jacobian_determinants(dn: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """`det J` at one point for each element, `(m,)` (no inverse: safe on degenerate elements)."""
    return np.linalg.det(dn @ xyz)


def nodal_mass(n_points, xyz: np.ndarray, shape_functions) -> np.ndarray:
    """Consistent mass `M_e = sum_g N^T N det J w_g` for `rho = 1`, `(m, 3n, 3n)`.

    `n_points` are `((xi, eta, zeta), weight)` pairs; `shape_functions(point)` returns `(N, dN)`.
    """
    n_nodes = xyz.shape[1]
    scalar = np.zeros((xyz.shape[0], n_nodes, n_nodes))
    for point, w in n_points:
        n, dn = shape_functions(*point)
        det, _ = jacobians(dn, xyz)
        scalar += (w * det)[:, None, None] * np.outer(n, n)[None]
    mass = np.zeros((xyz.shape[0], 3 * n_nodes, 3 * n_nodes))
    for c in range(3):
        mass[:, c::3, c::3] = scalar
    return mass


def _format_ids(ids, limit: int = 10) -> str:
    ids = [int(i) for i in ids]
    head = ", ".join(str(i) for i in ids[:limit])
    return head + (f", ... ({len(ids)} in all)" if len(ids) > limit else "")


def check_jacobians(name: str, det: np.ndarray, size: np.ndarray, min_ratio: float = MIN_JACOBIAN_RATIO,
                    reorder_hint: str = "") -> None:
    """Refuse inverted, degenerate and badly shaped elements from `det J` at sample points.

    **Arguments:**
    - `name`: the element type, for the message (`"H8"`, `"Tet10"`).
    - `det`: `(m, s)` `det J` at `s` sample points of each element (corners, Gauss points, centre).
    - `size`: `(m,)` a length of each element (its longest edge): `det J` is compared with `size^3`.
    - `min_ratio`: smallest admissible `min det J / max det J`.

    **Raises:** `ValueError` naming the elements: *inverted* (`det J < 0` at every point: the nodes
    are numbered in the mirrored order), *degenerate* (`det J` zero or of both signs: collapsed,
    flat or self-intersecting), *badly shaped* (ratio below `min_ratio`).
    """
    det = np.asarray(det, dtype=np.float64)
    if not np.all(np.isfinite(det)):
        bad = np.flatnonzero(~np.all(np.isfinite(det), axis=1))
        raise ValueError(f"{name} elements {_format_ids(bad)} have non-finite node coordinates.")
    tiny = DEGENERATE_RATIO * np.asarray(size, dtype=np.float64)[:, None] ** 3
    inverted = np.flatnonzero(np.all(det < -tiny, axis=1))
    if inverted.size:
        raise ValueError(
            f"{name} elements {_format_ids(inverted)} are inverted (det J < 0 everywhere: their nodes are numbered "
            f"in the mirrored order){reorder_hint}."
        )
    degenerate = np.flatnonzero(np.any(det <= tiny, axis=1))
    if degenerate.size:
        raise ValueError(
            f"{name} elements {_format_ids(degenerate)} are degenerate (det J vanishes or changes sign inside: "
            "collapsed, flat, folded or self-intersecting elements); remesh them."
        )
    ratio = det.min(axis=1) / det.max(axis=1)
    bad = np.flatnonzero(ratio < min_ratio)
    if bad.size:
        raise ValueError(
            f"{name} elements {_format_ids(bad)} are badly shaped (Jacobian ratio {ratio[bad].min():.3g} < "
            f"{min_ratio}); remesh them, or pass a lower min_jacobian_ratio (an argument of SolidMesh, read_solid_mesh "
            "and read_solid_groups) if you accept the loss of accuracy."
        )


class AbstractSolidElement(eqx.Module):
    """A solid (3D) element: unit matrices of a batch of elements from their nodes.

    Element matrices do not depend on the design: the stiffness is computed for `E = 1` and the
    mass for `rho = 1`; SIMP scales them per element. Degrees of freedom are ordered
    `(u_x, u_y, u_z)` per node, nodes in the VTK (meshio) order of the cell type `cell_type`.
    """

    n_nodes: eqx.AbstractClassVar[int]
    cell_type: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def jacobian_samples(self, xyz: np.ndarray) -> np.ndarray:
        """`det J` at the sample points of the shape check, `(m, s)`."""

    @abc.abstractmethod
    def reordered(self) -> np.ndarray:
        """The node permutation that mirrors an element (turns an inverted element into a valid one)."""

    @abc.abstractmethod
    def matrices(self, xyz: np.ndarray, poisson: float) -> tuple[np.ndarray, np.ndarray]:
        """Unit stiffness and consistent mass of each element.

        **Arguments:**
        - `xyz`: `(m, n_nodes, 3)` node coordinates in the element's node order.
        - `poisson`: Poisson ratio, in `[0, 0.5)`.

        **Returns:** `(K_e, M_e)`, NumPy arrays `(m, 3 n_nodes, 3 n_nodes)` each.

        **Raises:** `ValueError` naming inverted, degenerate or badly shaped elements.
        """

    def check(self, xyz: np.ndarray, min_ratio: float = MIN_JACOBIAN_RATIO, reorder_hint: str = "") -> None:
        """Refuse inverted, degenerate and badly shaped elements (see `check_jacobians`)."""
        xyz = np.asarray(xyz, dtype=np.float64)
        if xyz.ndim != 3 or xyz.shape[1:] != (self.n_nodes, 3):
            raise ValueError(f"{type(self).__name__} needs node coordinates of shape (m, {self.n_nodes}, 3), "
                             f"got {xyz.shape}.")
        edges = xyz[:, :, None, :] - xyz[:, None, :, :]
        size = np.sqrt(np.max(np.sum(edges**2, axis=-1), axis=(1, 2)))
        check_jacobians(type(self).__name__, self.jacobian_samples(xyz), size, min_ratio, reorder_hint)


def check_poisson(poisson: float) -> float:
    """`poisson` as a float in `[0, 0.5)`, or a `ValueError`."""
    if not 0.0 <= poisson < 0.5:
        raise ValueError(f"Poisson ratio must lie in [0, 0.5) (0.5 is incompressible), got {poisson}.")
    return float(poisson)
