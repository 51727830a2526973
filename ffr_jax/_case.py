"""A case: a scene whose flexible rod is shaped by a density design, with its objective.

The case is the design → parameter map of the data flow:
`x → (K(x), M(x)) → (Phi(x), omega(x)) → body data → scene p(x)`.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._body_data import BodyData, flexible_body_data
from ._fe import RodMesh, mass_matrix, stiffness_matrix
from ._geometric_stiffness import centrifugal_geometric_stiffness
from ._model import MinimalModel
from ._modes import ModalBasis, hinged_modes
from ._objective._base import AbstractIntegrand
from ._scene._scene import Scene
from ._scene._stiffening import GeometricStiffening
from ._simp import SIMP, RodDesign
from ._sparse_fe import resolve_fe_path, sparse_mass_matrix, sparse_stiffness_matrix
from ._sparse_modes import sparse_hinged_modes
from ._typing import Design


class FlexibleRodCase(eqx.Module):
    """A multibody scene with one density-parameterised flexible rod, an objective and a time span.

    - `design`: mesh, SIMP law and design-vector layout of the rod.
    - `n_modes`: retained hinged–hinged modes (REFERENCE_CASE §2).
    - `body`: index of the rod in the scene; `scene_template`: the scene with the rod's data at
      the initial design (only its structure and non-rod parameters are used).
    - `model`: the partitioned minimal-coordinate model.
    - `integrand`: `F` of `psi = int F dt`; `t0`, `t1`: time span; `y_r0`, `z_r0`: consistent
      redundant initial state; `jump_ts`: times where drivers switch pieces.
    - `fe_path`: `"dense"` (dense `K`, `M` and a full eigen-solution), `"sparse"` (matrix-free
      `K`, `M`, shift-invert Lanczos; for large meshes) or `"auto"` (sparse above
      `SPARSE_MIN_DOF` = 1,000 degrees of freedom, so the reference rod is sparse). Both give the
      same numbers and gradients; only the dense path supports forward mode (`jax.jvp`) in `x`.
    """

    design: RodDesign
    n_modes: int = eqx.field(static=True)
    body: int = eqx.field(static=True)
    scene_template: Scene
    model: MinimalModel
    integrand: AbstractIntegrand
    t0: float = eqx.field(static=True)
    t1: float = eqx.field(static=True)
    y_r0: jnp.ndarray
    z_r0: jnp.ndarray
    jump_ts: tuple[float, ...] = eqx.field(static=True, default=())
    fe_path: str = eqx.field(static=True, default="auto")

    def __check_init__(self):
        resolve_fe_path(self.fe_path, self.design.mesh)

    # --- the design side --------------------------------------------------------------------
    @property
    def mesh(self) -> RodMesh:
        return self.design.mesh

    @property
    def material(self) -> SIMP:
        return self.design.material

    @property
    def n_design(self) -> int:
        return self.design.n_design

    def initial_design(self, value: float = 0.5) -> Design:
        """A uniform design `x_e = value`, flat in the REFERENCE_CASE §1 order."""
        return self.design.initial_design(value)

    @property
    def fixed_dofs(self) -> tuple[int, ...]:
        """Hinged–hinged modal boundary conditions: `u_x(A)`, `u_y(A)`, `u_y(B)`."""
        a, b = self.mesh.node_a, self.mesh.node_b
        return (2 * a, 2 * a + 1, 2 * b + 1)

    @property
    def marker_nodes(self) -> tuple[int, ...]:
        """Joint points of the rod: marker 0 is A, marker 1 is B."""
        return (self.mesh.node_a, self.mesh.node_b)

    @property
    def sparse_fe(self) -> bool:
        """Whether this case takes the sparse FE path (`fe_path` resolved for its mesh)."""
        return resolve_fe_path(self.fe_path, self.mesh) == "sparse"

    def fe_matrices(self, x: Design):
        """`(K(x), M(x))`: dense `(n_dof, n_dof)` arrays, or on the sparse path matrix-free
        [`ElementOperator`][]s (which support `@`)."""
        x = self.design.check(x)
        xe = self.design.element_densities(x)
        youngs, densities = self.material.youngs(xe), self.material.densities(xe)
        if self.sparse_fe:
            return sparse_stiffness_matrix(self.mesh, youngs), sparse_mass_matrix(self.mesh, densities)
        return stiffness_matrix(self.mesh, youngs), mass_matrix(self.mesh, densities)

    def _hinged_modes(self, k, m) -> ModalBasis:
        solve = sparse_hinged_modes if self.sparse_fe else hinged_modes
        return solve(k, m, self.fixed_dofs, self.n_modes)

    def modes(self, x: Design) -> ModalBasis:
        k, m = self.fe_matrices(x)
        return self._hinged_modes(k, m)

    def frequencies(self, x: Design):
        """Retained natural frequencies in Hz, `(n_modes,)`."""
        return self.modes(x).frequencies

    def body_data(self, x: Design) -> BodyData:
        """Standard input data of the rod for design `x`."""
        k, m = self.fe_matrices(x)
        basis = self._hinged_modes(k, m)
        return flexible_body_data(self.mesh, m, k, basis.modes, self.marker_nodes)

    def scene(self, x: Design) -> Scene:
        """The parameter pytree `p(x)`: the scene with the rod's body data for design `x`.

        Design-dependent data of the rod's effects ([`GeometricStiffening`][]'s `K_geo`) are
        recomputed for `x` as well; a scene without such an effect computes nothing more.
        """
        stiffening = [i for i, f in enumerate(self.scene_template.forces)
                      if isinstance(f, GeometricStiffening) and f.body == self.body]
        if not stiffening:
            return self.with_body_data(self.body_data(x))
        if self.sparse_fe:
            raise ValueError(
                "Geometric stiffening needs the dense FE path (its pre-stress solve uses dense K); "
                "build the case with fe_path='dense' (meshes up to a few thousand degrees of freedom)."
            )
        x = self.design.check(x)
        youngs = self.material.youngs(self.design.element_densities(x))
        k, m = self.fe_matrices(x)
        modes = hinged_modes(k, m, self.fixed_dofs, self.n_modes).modes
        scene = self.with_body_data(flexible_body_data(self.mesh, m, k, modes, self.marker_nodes))
        k_geo = centrifugal_geometric_stiffness(self.mesh, k, m, youngs, modes, self.fixed_dofs)
        for i in stiffening:
            scene = eqx.tree_at(lambda s: s.forces[i].modal_geometric_stiffness, scene, k_geo)
        return scene

    def with_body_data(self, data: BodyData) -> Scene:
        return eqx.tree_at(lambda s: s.bodies[self.body].data, self.scene_template, data)

    # --- helpers ----------------------------------------------------------------------------
    def design_grid(self, values) -> np.ndarray:
        """Reshape a design-ordered vector to the `(ny, nx - 2)` grid (rows bottom to top)."""
        return np.asarray(values).reshape(self.mesh.ny, self.mesh.nx - 2)
