"""The reference rod as a solid: one layer of 8-node hexahedra through its thickness (issue 27).

The rod of REFERENCE_CASE §1 occupies `[0, L] x [-h/2, h/2] x [-b/2, b/2]`; [`box_grid`][]`(nx, ny, 1, L, h, b)`
meshes it with one layer of plain [`H8`][] elements, so that element `j nx + i` is the planar rod's element
`(i, j)` and carries its SIMP values: the design variables are the planar rod's, one per `(x, y)` element column.

**Reference conditions.** The planar modes hold `u_x(A)`, `u_y(A)`, `u_y(B)` (REFERENCE_CASE §2). A and B are now
lines of two nodes through the thickness (marker A at their centroid `(0, 0, 0)`, B at `(L, 0, 0)`). Held here: all
of `u_x, u_y, u_z` at both nodes of A, `u_y` and `u_z` at both nodes of B. This
- removes the six rigid motions: translations by A, the turn about `z` by `u_y(B)`, about `y` by `u_z(B)` (and the
  two `u_x` of A), about `x` (the roll, which the line A-B does not fix) by the two `u_y` of A;
- is the planar frame in space: A has no elastic displacement, B moves along the frame's x-axis only;
- is mirror-symmetric about the mid-plane `z = 0` (both nodes of a line held alike), so every mode is either
  symmetric (`u_x, u_y` even in `z`, `u_z` odd) or antisymmetric under the mirror;
- reduces, on the in-plane fields (`u_x, u_y` the same on both layers, `u_z = 0`), to the planar conditions: the
  `u_z` conditions hold there already, the two nodes of a line repeat one condition.

**In-plane modes are the Q4 modes (Poisson's ratio 0).** With `nu = 0` the in-plane fields are an invariant subspace
of `K` (their strains `e_zz`, `g_xz`, `g_yz` vanish and `nu = 0` couples no other strain to `e_zz`), on which the
2x2x2-Gauss `H8` stiffness and mass of one layer are the 2x2-Gauss `Q4` plane-stress ones of thickness `b` (the two
layers' trilinear functions sum to the bilinear ones, exactly integrated). So the in-plane eigenpairs of the solid
are those of the planar rod.

**Modes retained.** The mirror splits the modal problem into the symmetric and antisymmetric halves (`T_s`, `T_a`:
the node pairs' sums and differences; a standard symmetry reduction, exact for a mirror-symmetric body): the
`n_modes` lowest symmetric modes (the in-plane ones: the symmetric modes with `u_z != 0` stretch the thickness, tens
of kHz) and the `out_of_plane_modes` lowest antisymmetric ones (bending across the thickness, twist), each by the
subspace-stable `retained_eigenpairs`. The planar slider–crank is symmetric under the mirror too, so the
out-of-plane modes stay unexcited in its motion.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._design.design_map import AbstractDesignMap
from .._design.designed_body import DesignedBody
from .._design.element.h8 import H8
from .._design.material import SIMP
from .._design.modal.dense import retained_eigenpairs
from .._design.solid_assembly import SolidFEModel
from .._design.solid_mesh import box_grid
from .._scene._scene import Scene
from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from .._spatial._solid_body_data import solid_body_data
from ._rod import rod_body


def _pair_bases(n_pairs: int, held: set) -> tuple[np.ndarray, np.ndarray]:
    """`T_s`, `T_a` `(6 n_pairs, n_free)`: the symmetric and antisymmetric fields of the node pairs `(2 g, 2 g + 1)`
    (bottom, top) without the held pair degrees of freedom `(g, d)`."""
    t_s, t_a = [], []
    for g in range(n_pairs):
        for d in range(3):
            if (g, d) in held:
                continue
            s, a = np.zeros(6 * n_pairs), np.zeros(6 * n_pairs)
            bottom, top = 6 * g + d, 6 * g + 3 + d
            if d < 2:  # u_x, u_y: even (symmetric) or odd (antisymmetric) in z
                s[bottom], s[top], a[bottom], a[top] = 1.0, 1.0, -1.0, 1.0
            else:  # u_z: odd (symmetric) or even (antisymmetric)
                s[bottom], s[top], a[bottom], a[top] = -1.0, 1.0, 1.0, 1.0
            t_s.append(s)
            t_a.append(a)
    return np.stack(t_s, axis=1), np.stack(t_a, axis=1)


class SolidRod(AbstractDesignMap):
    """Design map of the one-layer solid rod (module docstring): the planar rod's densities -> spatial body data.

    Build it with [`solid_rod`][]. Fields: `rod` the planar [`DesignedBody`][] whose design layout, SIMP law and
    element values it uses; `model` the [`SolidFEModel`][] (`H8`); `n_modes` in-plane and `out_of_plane_modes`
    out-of-plane modes (static); `name` the scene body it writes (static).
    """

    rod: DesignedBody
    model: SolidFEModel
    n_modes: int = eqx.field(static=True)
    out_of_plane_modes: int = eqx.field(static=True)
    name: str = eqx.field(static=True)

    @property
    def n_design(self) -> int:
        return self.rod.n_design

    def initial_design(self, value=0.5):
        return self.rod.initial_design(value)

    def check(self, designs):
        if isinstance(designs, dict):
            if set(designs) != {self.name}:
                raise ValueError(f"The design has entries {sorted(designs)}; the designed body is {self.name!r}.")
            designs = designs[self.name]
        return self.rod.domain.check(designs, self.rod.material.x_min, body=self.name)

    def check_scene(self, scene: Scene) -> None:
        data = scene.bodies[scene.body_index(self.name)].data
        n_q = self.n_modes + self.out_of_plane_modes
        if not isinstance(data, SpatialFlexibleBodyData) or data.n_modes != n_q or data.marker_positions.shape[0] != 2:
            raise ValueError(f"The scene's body {self.name!r} must be a spatial flexible body with {n_q} modes and "
                             "2 markers (A, B): build it from SolidRod.body_data.")

    def __call__(self, designs, scene: Scene) -> Scene:
        index = scene.body_index(self.name)
        return eqx.tree_at(lambda s: s.bodies[index].data, scene, self.body_data(designs))

    # --- the chain -------------------------------------------------------------------------------------
    def _bases(self):
        mesh = self.model.mesh
        ny = mesh.shape[1]
        a, b = ny // 2, mesh.shape[0] * (ny + 1) + ny // 2  # planar A, B: node pairs (2 a, 2 a + 1), (2 b, 2 b + 1)
        held = {(a, 0), (a, 1), (a, 2), (b, 1), (b, 2)}
        return _pair_bases(mesh.n_nodes // 2, held), ((2 * a, 2 * a + 1), (2 * b, 2 * b + 1))

    def matrices(self, x):
        """Matrix-free `(K(x), M(x))` of the solid rod (SIMP values of the planar rod's elements)."""
        youngs, densities = self.rod.element_values(self.check(x))
        return self.model.stiffness(youngs), self.model.mass(densities)

    def eigenpairs(self, x):
        """`(lam, Phi)`: `(n_q,)` `omega^2` and `(n_dof, n_q)` M-orthonormal modes, the `n_modes` in-plane ones first
        (ascending), then the `out_of_plane_modes` antisymmetric ones (ascending)."""
        k, m = self.matrices(x)
        (t_s, t_a), _ = self._bases()
        parts = []
        for t, n in ((t_s, self.n_modes), (t_a, self.out_of_plane_modes)):
            if n == 0:
                continue
            t = jnp.asarray(t)
            k_r, m_r = t.T @ (k @ t), t.T @ (m @ t)
            lam, phi = retained_eigenpairs(0.5 * (k_r + k_r.T), 0.5 * (m_r + m_r.T), n)
            parts.append((lam, t @ phi))
        return jnp.concatenate([p[0] for p in parts]), jnp.concatenate([p[1] for p in parts], axis=1)

    def frequencies(self, x):
        """Eigenfrequencies of the retained modes in Hz (in-plane, then out-of-plane)."""
        return jnp.sqrt(self.eigenpairs(x)[0]) / (2 * jnp.pi)

    def body_data(self, x) -> SpatialFlexibleBodyData:
        """The spatial body data ([`solid_body_data`][]) of the solid rod at design `x`; markers A, B the node
        lines through the thickness (their rotations from the elements around them)."""
        k, m = self.matrices(x)
        _, modes = self.eigenpairs(x)
        _, markers = self._bases()
        return solid_body_data(self.model.mesh.nodes, k, m, modes, markers, elements=self.model.mesh.elements)


def solid_rod(nx: int = 100, ny: int = 6, n_modes: int = 6, *, out_of_plane_modes: int = 0, length: float = 1.0,
              height: float = 0.06, thickness: float = 0.01, poisson: float = 0.3,
              material: SIMP = SIMP()) -> SolidRod:
    """The reference rod meshed with one layer of `H8` through its thickness, as a design map (module docstring).

    **Arguments:** `nx`, `ny` (`ny` even), `length`, `height`, `thickness`, `material` as [`rod_body`][] (the same
    design variables); `n_modes` in-plane and `out_of_plane_modes` out-of-plane modes; `poisson` (with 0 the
    in-plane modes are the planar rod's with `poisson=0`).

    **Returns:** a [`SolidRod`][] design map for the scene body `"rod"`.
    """
    for label, value, low in (("n_modes", n_modes, 1), ("out_of_plane_modes", out_of_plane_modes, 0)):
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise ValueError(f"solid_rod({label}=...) must be an int >= {low}, got {value!r}.")
    rod = rod_body(nx, ny, n_modes, length=length, height=height, thickness=thickness, poisson=poisson,
                   material=material)
    mesh = box_grid(nx, ny, 1, length, height, thickness)
    planar = rod.model.mesh
    centroids = mesh.nodes[mesh.elements].mean(axis=1)[:, :2]
    if not np.allclose(centroids, planar.nodes[planar.elements].mean(axis=1), rtol=0, atol=1e-12 * length):
        raise AssertionError("box_grid's element order differs from the planar rod's")  # a broken invariant
    return SolidRod(rod, SolidFEModel(mesh, H8(), poisson), n_modes, out_of_plane_modes, "rod")
