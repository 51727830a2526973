"""A case: a [`Problem`][] whose parameters come from designs through a design map.

`designs -> (design map) -> scene p(x) -> (problem) -> motion -> psi`: the design map
(`ffr_jax._design.design_map`) is the design stage of the data flow, the problem maps the scene to
the motion and `psi`.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._design.design_map import AbstractDesignMap
from .._design.designed_body import DesignedBody
from .._design.material import SIMP
from .._design.mesh import QuadMesh
from .._design.solid_designed_body import SolidDesignedBody
from .._design.solid_mesh import SolidMesh
from ._problem import Problem
from .._scene._scene import Scene


class Case(eqx.Module):
    """A [`Problem`][] whose parameters come from designs: `psi(x) = psi(problem with p(x))`.

    - `problem`: the mechanism, time span, initial state and objective; its scene is a template
      (only its structure and the parameters that are not designed are used).
    - `design_map`: `x -> p(x)`, a [`DesignMap`][] of the designed bodies (the rod of the paper
      is one [`DesignedBody`][]).

    `ffr_jax.value_and_grad(case, x)` differentiates `psi` with respect to the designs `x` (a
    dict by body name, or a flat array when one body is designed) by one VJP of the design map
    after any sensitivity method. The case forwards the design map's methods (`n_design`,
    `initial_design`, `check`, `frequencies`, `modes`, `body_data`), the problem's attributes
    (`model`, `t1`, ...), and, with exactly one designed body, that body's (`design`, `mesh`,
    `material`, `n_modes`, `fixed_dofs`, `marker_nodes`, `fe_matrices`, `design_grid`).
    """

    problem: Problem
    design_map: AbstractDesignMap

    def __check_init__(self):
        if not isinstance(self.problem, Problem):
            raise TypeError(f"problem must be an ffr_jax.Problem, got {type(self.problem).__name__}.")
        if not isinstance(self.design_map, AbstractDesignMap):
            raise TypeError(f"design_map must be a design map (e.g. ffr_jax.DesignMap), got "
                            f"{type(self.design_map).__name__}.")
        self.design_map.check_scene(self.problem.scene)

    def scene(self, x) -> Scene:
        """The parameter pytree `p(x)`."""
        return self.design_map(x, self.problem.scene)

    def problem_for(self, x) -> Problem:
        """The problem at designs `x`."""
        return self.problem.with_scene(self.scene(x))

    def with_objective(self, objective, *, check_terminal: bool = True) -> "Case":
        """The same case with another objective (e.g. `ffr_jax.KineticEnergy()` or an [`Objective`][])."""
        return eqx.tree_at(lambda c: c.problem, self, self.problem.with_objective(objective,
                                                                                 check_terminal=check_terminal))

    # --- the design map ------------------------------------------------------------------------
    @property
    def n_design(self) -> int:
        return self.design_map.n_design

    def initial_design(self, value=0.5):
        """A uniform design `x_e = value` (a flat array with one designed body, else a dict by body)."""
        return self.design_map.initial_design(value)

    def check(self, x):
        return self.design_map.check(x)

    def modes(self, x):
        return self.design_map.modes(x)

    def frequencies(self, x):
        """Retained natural frequencies in Hz of the designed bodies (`(n_modes,)` for one body)."""
        return self.design_map.frequencies(x)

    def body_data(self, x):
        return self.design_map.body_data(x)

    # --- the one designed body (the rod cases) -------------------------------------------------
    @property
    def design(self) -> DesignedBody | SolidDesignedBody:
        """The designed body, when the case has exactly one (e.g. for `ffr_jax.DensityFilter(case.design, r)`)."""
        return self.design_map.only

    @property
    def mesh(self) -> QuadMesh | SolidMesh:
        return self.design.mesh

    @property
    def material(self) -> SIMP:
        return self.design.material

    @property
    def n_modes(self) -> int:
        return self.design.n_modes

    @property
    def fixed_dofs(self) -> tuple[int, ...]:
        return self.design.fixed_dofs

    @property
    def marker_nodes(self) -> tuple:
        return self.design.markers

    def fe_matrices(self, x) -> tuple[jnp.ndarray, jnp.ndarray]:
        """Dense `(K(x), M(x))`, `(n_dof, n_dof)` each (small meshes; `case.design.matrices(x)` is matrix-free)."""
        k, m = self.design.matrices(x)
        return k.todense(), m.todense()

    def design_grid(self, values) -> np.ndarray:
        """A design-ordered vector on the rod's grid, `(ny, nx - 2)` (rows bottom to top)."""
        return self.design.domain.design_grid(values)

    # --- the problem ---------------------------------------------------------------------------
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
