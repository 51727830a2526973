"""Reference conditions of the floating frame: the degrees of freedom a modal basis holds at zero.

The reference conditions tie the body frame to the body: every shape vector vanishes on the
fixed degrees of freedom, which must remove the three rigid-body motions of the plane body
(otherwise the modal analysis fails with a clear error).
"""

import abc

import equinox as eqx
import numpy as np

from ..mesh import QuadMesh


class AbstractReference(eqx.Module):
    """Reference conditions: a static set of degrees of freedom held at zero."""

    @abc.abstractmethod
    def fixed_dofs(self, mesh: QuadMesh) -> tuple[int, ...]:
        """The held degrees of freedom (`2 n` is `u_x` of node `n`, `2 n + 1` its `u_y`), sorted."""


class FixedDofs(AbstractReference):
    """Any set of degrees of freedom held at zero."""

    dofs: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, dofs):
        self.dofs = tuple(sorted({int(d) for d in dofs}))

    def fixed_dofs(self, mesh: QuadMesh) -> tuple[int, ...]:
        bad = [d for d in self.dofs if not 0 <= d < mesh.n_dof]
        if bad:
            raise ValueError(f"FixedDofs: degrees of freedom {bad} are not in the mesh ({mesh.n_dof} dofs).")
        return self.dofs


class HingedHinged(AbstractReference):
    """The paper's hinged–hinged frame (REFERENCE_CASE §2): `A` held, `B` free along the line A–B.

    Holds `u_x(A)`, `u_y(A)` and the displacement of `B` across the line A–B, which must run
    along the x- or the y-axis of the body frame (for the rod: `u_y(B)`). The body frame then
    has its origin at `A` and its x-axis through `B` when A–B lies along x.
    """

    node_a: int = eqx.field(static=True)
    node_b: int = eqx.field(static=True)

    def fixed_dofs(self, mesh: QuadMesh) -> tuple[int, ...]:
        a, b = mesh.check_nodes((self.node_a, self.node_b), "HingedHinged nodes")
        d = mesh.nodes[b] - mesh.nodes[a]
        tol = 1e-12 * np.linalg.norm(d)
        if abs(d[1]) <= tol:
            across = 2 * b + 1
        elif abs(d[0]) <= tol:
            across = 2 * b
        else:
            raise ValueError(
                "HingedHinged needs the line A-B along the x- or y-axis of the body frame (B slides along it); "
                f"got A={mesh.nodes[a]}, B={mesh.nodes[b]}. Hold other degrees of freedom with FixedDofs."
            )
        return tuple(sorted((2 * a, 2 * a + 1, across)))


class Clamped(AbstractReference):
    """Every degree of freedom of `nodes` held (e.g. one end clamped: a clamped–free frame)."""

    nodes: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, nodes):
        self.nodes = tuple(int(n) for n in np.asarray(nodes).ravel())

    def fixed_dofs(self, mesh: QuadMesh) -> tuple[int, ...]:
        nodes = mesh.check_nodes(self.nodes, "Clamped nodes")
        return tuple(sorted(d for n in nodes for d in (2 * n, 2 * n + 1)))
