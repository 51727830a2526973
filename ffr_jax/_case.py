"""A case: a [`Problem`][] whose parameters come from a density design through a design map.

The design map is the design → parameter stage of the data flow:
`x → (K(x), M(x)) → (Phi(x), omega(x)) → body data → scene p(x)`; the problem maps the scene to
the motion and `psi`.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._body_data import BodyData, flexible_body_data
from ._checks import integer
from ._fe import RodMesh, mass_matrix, stiffness_matrix
from ._geometric_stiffness import centrifugal_geometric_stiffness
from ._modes import ModalBasis, hinged_modes
from ._problem import Problem
from ._scene._scene import Scene
from ._scene._stiffening import GeometricStiffening
from ._simp import SIMP, RodDesign
from ._sparse_fe import resolve_fe_path, sparse_mass_matrix, sparse_stiffness_matrix
from ._sparse_modes import sparse_hinged_modes
from ._typing import Design, DesignInput


class AbstractDesignMap(eqx.Module):
    """A design → parameters map: writes the data of the designed bodies for design `x` into a scene."""

    @property
    @abc.abstractmethod
    def n_design(self) -> int:
        """Number of design variables."""

    @abc.abstractmethod
    def initial_design(self, value: float = 0.5) -> Design:
        """A uniform design."""

    @abc.abstractmethod
    def check(self, x: DesignInput) -> Design:
        """Validate a design (shape at trace time, values at run time) and return it as float64."""

    @abc.abstractmethod
    def __call__(self, x: Design, scene: Scene) -> Scene:
        """The scene `p(x)`: `scene` with the designed bodies' data for design `x`."""


class RodDesignMap(AbstractDesignMap):
    """The density-designed flexible rod of REFERENCE_CASE §1–2 as body `body` of a scene.

    - `design`: mesh, SIMP law and design-vector layout of the rod.
    - `n_modes`: retained hinged–hinged modes (REFERENCE_CASE §2).
    - `body`: index of the rod in the scene.
    - `fe_path`: `"dense"` (dense `K`, `M` and a full eigen-solution), `"sparse"` (matrix-free
      `K`, `M`, shift-invert Lanczos; for large meshes) or `"auto"` (sparse above
      `SPARSE_MIN_DOF` = 1,000 degrees of freedom, so the reference rod is sparse). Both give the
      same numbers and gradients; only the dense path supports forward mode (`jax.jvp`) in `x`.
    """

    design: RodDesign
    n_modes: int = eqx.field(static=True)
    body: int = eqx.field(static=True, default=0)
    fe_path: str = eqx.field(static=True, default="auto")

    def __check_init__(self):
        integer(self.n_modes, "RodDesignMap(n_modes=...)", 1, "It is the number of retained modes (REFERENCE_CASE: 6).")
        integer(self.body, "RodDesignMap(body=...)", 0)
        resolve_fe_path(self.fe_path, self.design.mesh)

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

    def check(self, x: DesignInput) -> Design:
        return self.design.check(x)

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
        """Whether this rod takes the sparse FE path (`fe_path` resolved for its mesh)."""
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

    def __call__(self, x: Design, scene: Scene) -> Scene:
        """The parameter pytree `p(x)`: `scene` with the rod's body data for design `x`.

        Design-dependent data of the rod's effects ([`GeometricStiffening`][]'s `K_geo`) are
        recomputed for `x` as well; a scene without such an effect computes nothing more.
        """
        stiffening = [i for i, f in enumerate(scene.forces) if isinstance(f, GeometricStiffening) and f.body == self.body]
        if not stiffening:
            return self.with_body_data(scene, self.body_data(x))
        if self.sparse_fe:
            raise ValueError(
                "Geometric stiffening needs the dense FE path (its pre-stress solve uses dense K); "
                "build the case with fe_path='dense' (meshes up to a few thousand degrees of freedom)."
            )
        x = self.design.check(x)
        youngs = self.material.youngs(self.design.element_densities(x))
        k, m = self.fe_matrices(x)
        modes = hinged_modes(k, m, self.fixed_dofs, self.n_modes).modes
        scene = self.with_body_data(scene, flexible_body_data(self.mesh, m, k, modes, self.marker_nodes))
        k_geo = centrifugal_geometric_stiffness(self.mesh, k, m, youngs, modes, self.fixed_dofs)
        for i in stiffening:
            scene = eqx.tree_at(lambda s: s.forces[i].modal_geometric_stiffness, scene, k_geo)
        return scene

    def with_body_data(self, scene: Scene, data: BodyData) -> Scene:
        return eqx.tree_at(lambda s: s.bodies[self.body].data, scene, data)

    def design_grid(self, values) -> np.ndarray:
        """Reshape a design-ordered vector to the `(ny, nx - 2)` grid (rows bottom to top)."""
        return np.asarray(values).reshape(self.mesh.ny, self.mesh.nx - 2)


class Case(eqx.Module):
    """A [`Problem`][] whose parameters come from a density design: `psi(x) = psi(problem with p(x))`.

    - `problem`: the mechanism, time span, initial state and objective; its scene is a template
      (only its structure and the parameters that are not designed are used).
    - `design_map`: `x -> p(x)` ([`RodDesignMap`][] for the rod of the paper).

    `ffr_jax.value_and_grad(case, x)` differentiates `psi` with respect to `x` (one VJP of the design
    map after any sensitivity method). The case forwards the design map's and the problem's common
    attributes (`n_design`, `initial_design`, `frequencies`, `model`, `t1`, ...).
    """

    problem: Problem
    design_map: AbstractDesignMap

    def scene(self, x: Design) -> Scene:
        """The parameter pytree `p(x)`."""
        return self.design_map(x, self.problem.scene)

    def problem_for(self, x: Design) -> Problem:
        """The problem at design `x`."""
        return self.problem.with_scene(self.scene(x))

    def with_objective(self, objective, *, check_terminal: bool = True) -> "Case":
        """The same case with another objective (e.g. `ffr_jax.KineticEnergy()` or an [`Objective`][])."""
        return eqx.tree_at(lambda c: c.problem, self, self.problem.with_objective(objective,
                                                                                 check_terminal=check_terminal))

    # --- the design side --------------------------------------------------------------------
    @property
    def n_design(self) -> int:
        return self.design_map.n_design

    def initial_design(self, value: float = 0.5) -> Design:
        """A uniform design `x_e = value` (flat, in design order)."""
        return self.design_map.initial_design(value)

    def check(self, x: DesignInput) -> Design:
        return self.design_map.check(x)

    @property
    def design(self) -> RodDesign:
        return self.design_map.design

    @property
    def mesh(self) -> RodMesh:
        return self.design_map.mesh

    @property
    def material(self) -> SIMP:
        return self.design_map.material

    @property
    def n_modes(self) -> int:
        return self.design_map.n_modes

    @property
    def body(self) -> int:
        return self.design_map.body

    @property
    def fe_path(self) -> str:
        return self.design_map.fe_path

    @property
    def fixed_dofs(self) -> tuple[int, ...]:
        return self.design_map.fixed_dofs

    @property
    def marker_nodes(self) -> tuple[int, ...]:
        return self.design_map.marker_nodes

    @property
    def sparse_fe(self) -> bool:
        return self.design_map.sparse_fe

    def fe_matrices(self, x: Design):
        return self.design_map.fe_matrices(x)

    def modes(self, x: Design) -> ModalBasis:
        return self.design_map.modes(x)

    def frequencies(self, x: Design):
        """Retained natural frequencies in Hz of the designed body, `(n_modes,)`."""
        return self.design_map.frequencies(x)

    def body_data(self, x: Design) -> BodyData:
        return self.design_map.body_data(x)

    def with_body_data(self, data: BodyData) -> Scene:
        return self.design_map.with_body_data(self.problem.scene, data)

    def design_grid(self, values) -> np.ndarray:
        return self.design_map.design_grid(values)

    # --- the problem side -------------------------------------------------------------------
    @property
    def scene_template(self) -> Scene:
        return self.problem.scene

    @property
    def model(self):
        return self.problem.model

    @property
    def objective(self):
        return self.problem.objective

    @property
    def integrand(self):
        return self.problem.objective.integrand

    @property
    def t0(self) -> float:
        return self.problem.t0

    @property
    def t1(self) -> float:
        return self.problem.t1

    @property
    def jump_ts(self) -> tuple[float, ...]:
        return self.problem.jump_ts

    @property
    def y_r0(self) -> jnp.ndarray:
        """Consistent redundant initial positions (of the template scene)."""
        return self.problem.y_r0

    @property
    def z_r0(self) -> jnp.ndarray:
        """Consistent redundant initial velocities (of the template scene)."""
        return self.problem.z_r0


# The name of the one-rod case before the problem type existed.
FlexibleRodCase = Case
