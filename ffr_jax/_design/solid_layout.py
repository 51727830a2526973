"""The layout of a solid part's modal basis: held and interior degrees of freedom.

The solid counterpart of `ReductionLayout` for the modal solvers (`DenseModes`, `LanczosModes`,
`AutoModes`): the supports (reference conditions of the floating frame) are held, everything else is
interior; no interfaces, so no static modes. Held degrees of freedom must remove the six rigid motions
(`rigid_motions` restricted to them has rank 6), so that `K_II` is positive definite; with none held (a free
part) the layout has six rigid-body modes (`n_rigid`, `rigid`), which `LanczosModes` computes and drops.
"""

import functools
import hashlib

import numpy as np
import scipy.sparse as sp

from .solid_assembly import solid_csc_pattern
from .solid_mesh import SolidMesh


def rigid_motions(nodes: np.ndarray) -> np.ndarray:
    """The six rigid motions of the nodes `(n_nodes, 3)`, `(3 n_nodes, 6)`: translations `x, y, z`, then
    rotations about the axes through the centroid of the nodes, scaled to unit rim displacement."""
    nodes = np.asarray(nodes, dtype=np.float64)
    rel = nodes - nodes.mean(axis=0)
    rel = rel / np.sqrt(np.mean(np.sum(rel**2, axis=1)))
    n = nodes.shape[0]
    r = np.zeros((n, 3, 6))
    r[:, 0, 0] = r[:, 1, 1] = r[:, 2, 2] = 1.0
    x, y, z = rel.T
    r[:, 1, 3], r[:, 2, 3] = -z, y  # about x
    r[:, 0, 4], r[:, 2, 4] = z, -x  # about y
    r[:, 0, 5], r[:, 1, 5] = -y, x  # about z
    return r.reshape(3 * n, 6)


class SolidReductionLayout:
    """Held (`fixed`, sorted) and interior degrees of freedom of a solid mesh; hashable by content.

    Offers what the modal solvers read from a `ReductionLayout`: `mesh`, `fixed`, `boundary` (empty),
    `patterns` `(0, 0)`, `removed` (= `fixed`), `interior`, `touching` (empty), `n_static` (0), `n_interior`,
    `n_rigid` (6 for a free part, else 0), `rigid` (the rigid motions `(n_dof, n_rigid)`) and `csc_matrices`
    (the host `K_II`, `M_II`).

    **Raises** `ValueError` if a held degree of freedom is not on the mesh or the held ones (if any) leave a rigid
    motion free.
    """

    def __init__(self, mesh: SolidMesh, fixed: tuple[int, ...]):
        self.mesh = mesh
        self.fixed = tuple(sorted({int(d) for d in fixed}))
        bad = [d for d in self.fixed if not 0 <= d < mesh.n_dof]
        if bad:
            raise ValueError(f"Held degrees of freedom {bad[:6]} are not on the mesh ({mesh.n_dof} dofs).")
        rank = int(np.linalg.matrix_rank(rigid_motions(mesh.nodes)[list(self.fixed)], tol=1e-9)) if self.fixed else 0
        if self.fixed and rank < 6:
            raise ValueError(
                f"The supports do not remove the rigid-body motions of the solid part (the held degrees of freedom "
                f"constrain rank {rank} of its 6 rigid motions): hold x, y, z on a face or node set, and y, z on a "
                "second set away from it (and one more direction off their line), e.g. supports={'big_bore': 'xyz', "
                "'small_bore': 'yz'}."
            )
        self.boundary = ()
        self.patterns = np.zeros((0, 0))
        self.patterns.flags.writeable = False
        self.removed = self.fixed
        self.interior = np.setdiff1d(np.arange(mesh.n_dof), np.asarray(self.fixed, dtype=np.int64))
        self.interior.flags.writeable = False
        self.touching = np.zeros(0, dtype=np.int64)
        digest = hashlib.sha256(mesh.digest.encode())
        digest.update(np.asarray(self.fixed, dtype=np.int64).tobytes())
        self.digest = digest.hexdigest()

    @property
    def n_static(self) -> int:
        return 0

    @property
    def n_interior(self) -> int:
        return self.interior.size

    @property
    def n_rigid(self) -> int:
        """Rigid-body modes of the interior problem: six for a free part, none with supports."""
        return 0 if self.fixed else 6

    @property
    def rigid(self) -> np.ndarray:
        """The rigid motions left free, `(n_dof, n_rigid)`."""
        return rigid_motions(self.mesh.nodes)[:, : self.n_rigid]

    def csc_matrices(self, youngs, densities, unit_stiffness, unit_mass) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """Host `K_II`, `M_II` (SciPy CSC) for element values `(n_elements,)` and unit matrices `(n_elements, d, d)`."""
        pattern = solid_csc_pattern(self.mesh, self.removed)
        return pattern.matrix(youngs, unit_stiffness), pattern.matrix(densities, unit_mass)

    def __hash__(self) -> int:
        return hash(self.digest)

    def __eq__(self, other) -> bool:
        return isinstance(other, SolidReductionLayout) and other.digest == self.digest


@functools.lru_cache(maxsize=16)
def solid_reduction_layout(mesh: SolidMesh, fixed: tuple[int, ...]) -> SolidReductionLayout:
    """The (cached) `SolidReductionLayout` of held degrees of freedom `fixed` on a solid mesh."""
    return SolidReductionLayout(mesh, fixed)
