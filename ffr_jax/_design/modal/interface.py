"""Interfaces (joint regions) and the layout of a Craig–Bampton basis on a mesh.

An interface is a set of nodes where the body is joined to others. Its static modes are the
Craig–Bampton constraint modes: a unit displacement pattern on the interface, the other
interfaces and the reference conditions held, the interior in static equilibrium,

`Psi_I = -K_II^-1 K_IB U_B`,  `Psi_B = U_B`,  `Psi = 0` on the fixed degrees of freedom,

and the eigenmodes are computed with all interface degrees of freedom held (fixed-interface
normal modes). With `rigid=False` the patterns `U_B` are the unit vectors of every interface
degree of freedom (two static modes per node); with `rigid=True` the interface moves as a rigid
body (two translations and a rotation about the centroid of its nodes: three static modes, and
the eigenmodes keep the interface at rest), the usual model of a pin in a solid bushing.

!!! cite "Reference"
    R. R. Craig, M. C. C. Bampton, "Coupling of substructures for dynamic analyses", AIAA J. 6
    (1968) 1313–1319.
"""

import functools
import hashlib

import equinox as eqx
import numpy as np

from ..assembly import csc_matrices
from ..mesh import QuadMesh, _format_ids


class Interface(eqx.Module):
    """A set of interface nodes and how it moves in its static modes (see the module docstring).

    - `nodes`: node indices (static).
    - `rigid`: `False`: one static mode per free degree of freedom of the nodes;
      `True`: three rigid-motion static modes (needs at least two nodes, none of them held by
      the reference conditions).
    """

    nodes: tuple[int, ...] = eqx.field(static=True)
    rigid: bool = eqx.field(static=True, default=False)

    def __init__(self, nodes, rigid: bool = False):
        self.nodes = tuple(int(n) for n in np.asarray(nodes).ravel())
        self.rigid = bool(rigid)

    def patterns(self, mesh: QuadMesh, fixed: frozenset) -> tuple[tuple[int, ...], np.ndarray]:
        """Interface degrees of freedom `B` and displacement patterns `U_B` `(n_B, n_static)`."""
        nodes = mesh.check_nodes(self.nodes, "Interface nodes")
        dofs = [d for n in nodes for d in (2 * n, 2 * n + 1)]
        if not self.rigid:
            free = tuple(d for d in dofs if d not in fixed)
            if not free:
                raise ValueError("Interface: every degree of freedom of its nodes is held by the reference "
                                 "conditions, so it has no static mode; drop it.")
            return free, np.eye(len(free))
        held = [d for d in dofs if d in fixed]
        if held:
            raise ValueError(
                f"A rigid Interface may not contain held degrees of freedom ({held[:6]}...): the reference "
                "conditions already fix it; drop the interface or use rigid=False."
            )
        if len(nodes) < 2:
            raise ValueError("A rigid Interface needs at least two nodes (a rotation about one node is undefined).")
        xy = mesh.nodes[list(nodes)]
        rel = xy - xy.mean(axis=0)
        radius = np.sqrt(np.mean(np.sum(rel**2, axis=1)))
        u = np.zeros((len(dofs), 3))
        u[0::2, 0] = 1.0
        u[1::2, 1] = 1.0
        u[0::2, 2] = -rel[:, 1] / radius  # rotation about the centroid, scaled to unit rim displacement
        u[1::2, 2] = rel[:, 0] / radius
        return tuple(dofs), u


def _rigid_rank(mesh: QuadMesh, fixed: tuple[int, ...]) -> int:
    """Rank of the plane rigid motions (`u_x`, `u_y`, rotation) restricted to the held dofs (3 if they fix the body)."""
    if not fixed:
        return 0
    fixed = np.asarray(fixed)
    xy = mesh.nodes - mesh.nodes.mean(axis=0)
    xy = xy / np.abs(xy).max()
    node, is_y = np.divmod(fixed, 2)
    rows = np.stack([1.0 - is_y, is_y.astype(float), np.where(is_y, xy[node, 0], -xy[node, 1])], axis=1)
    return int(np.linalg.matrix_rank(rows, tol=1e-9))


class ReductionLayout:
    """The static layout of a modal basis on one mesh: held, interface and interior dofs, patterns.

    Hashable by content (it keys compiled programs and host-side caches).

    - `fixed`: reference conditions `F`; `boundary`: interface degrees of freedom `B`;
      `removed = F + B` (held in the eigenproblem); `interior`: the rest, `I`.
    - `patterns`: `(n_B, n_static)` block-diagonal interface patterns `U_B`.
    - `touching`: elements with a node in `B` (the only ones `K_IB U_B` needs).
    """

    def __init__(self, mesh: QuadMesh, fixed: tuple[int, ...], interfaces: tuple[Interface, ...]):
        self.mesh = mesh
        self.fixed = tuple(sorted(set(fixed)))
        fixed_set = frozenset(self.fixed)
        rank = _rigid_rank(mesh, self.fixed)
        if rank < 3:
            raise ValueError(
                f"The reference conditions do not remove the rigid-body motions (the held degrees of freedom "
                f"constrain rank {rank} of the 3 plane rigid motions): hold both displacements of one node and one "
                "more displacement elsewhere (e.g. HingedHinged(a, b)), or clamp a set of nodes."
            )
        boundary, blocks, owner = [], [], {}
        for k, interface in enumerate(interfaces):
            dofs, u = interface.patterns(mesh, fixed_set)
            shared = [d for d in dofs if d in owner]
            if shared:
                raise ValueError(f"Interfaces {owner[shared[0]]} and {k} share nodes "
                                 f"{_format_ids(sorted({d // 2 for d in shared}))}; interfaces must be disjoint.")
            owner.update({d: k for d in dofs})
            boundary.extend(dofs)
            blocks.append(u)
        self.boundary = tuple(boundary)
        n_static = sum(b.shape[1] for b in blocks)
        patterns = np.zeros((len(boundary), n_static))
        r = c = 0
        for b in blocks:
            patterns[r : r + b.shape[0], c : c + b.shape[1]] = b
            r, c = r + b.shape[0], c + b.shape[1]
        patterns.flags.writeable = False
        self.patterns = patterns
        self.removed = tuple(sorted(fixed_set | set(boundary)))
        self.interior = np.setdiff1d(np.arange(mesh.n_dof), np.asarray(self.removed, dtype=np.int64))
        self.interior.flags.writeable = False
        if boundary:
            boundary_nodes = np.unique(np.asarray(boundary) // 2)
            self.touching = np.flatnonzero(np.any(np.isin(mesh.elements, boundary_nodes), axis=1))
        else:
            self.touching = np.zeros(0, dtype=np.int64)
        digest = hashlib.sha256(mesh.digest.encode())
        for part in (self.fixed, self.boundary):
            digest.update(np.asarray(part, dtype=np.int64).tobytes() + b"|")
        digest.update(patterns.tobytes())
        self.digest = digest.hexdigest()

    @property
    def n_static(self) -> int:
        return self.patterns.shape[1]

    @property
    def n_interior(self) -> int:
        return self.interior.size

    @property
    def n_rigid(self) -> int:
        """Rigid-body modes left free: none (the reference conditions remove the plane rigid motions)."""
        return 0

    def csc_matrices(self, youngs, densities, unit_stiffness, unit_mass):
        """Host `K_II`, `M_II` (SciPy CSC) for element values `(n_elements,)` and unit matrices `(n_elements, 8, 8)`."""
        return csc_matrices(self.mesh, youngs, densities, unit_stiffness, unit_mass, self.removed)

    def __hash__(self) -> int:
        return hash(self.digest)

    def __eq__(self, other) -> bool:
        return isinstance(other, ReductionLayout) and other.digest == self.digest


@functools.lru_cache(maxsize=32)
def reduction_layout(mesh: QuadMesh, fixed: tuple[int, ...], interfaces: tuple[Interface, ...]) -> ReductionLayout:
    """The (cached) [`ReductionLayout`][] of reference conditions and interfaces on a mesh."""
    return ReductionLayout(mesh, fixed, interfaces)
