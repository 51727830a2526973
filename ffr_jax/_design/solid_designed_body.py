"""A density-designed solid part: the pure map from its design vector to its spatial body data.

`x -> x_e (roles) -> (E_e, rho_e) (SIMP) -> (K, M) -> (lam, Phi) (modes with supports) -> spatial body data`

The 3-D counterpart of [`DesignedBody`][]. Supports, interface nodes (markers) and passive regions are named by the
mesh's physical groups ([`PhysicalGroups`][]): no node or element is searched by position. Every stage is JAX and
differentiable in the densities. The modes of a supported part come from the planar chain's modal solvers on the
interior problem (the supports held): [`DenseModes`][] (dense, subspace-stable [`retained_eigenpairs`][]),
[`LanczosModes`][] (sparse shift-invert Lanczos on the host, the derivative by sparse complement solves: memory and
time about linear in the mesh size, to 10^5 elements) or [`AutoModes`][] (the default: Lanczos above 1,000 degrees
of freedom). Both derivatives divide only by gaps between retained and discarded eigenvalues, so they stay finite and
exact for span-invariant quantities (the body data) where retained eigenvalues cross or coincide. A free part (no
supports) takes [`free_modes_dense`][] where the option picks the dense solver, and [`LanczosModes`][] otherwise (the
six rigid-body modes computed with a shift below zero and dropped; their part of the derivative, `-R R^T dM Phi`, is
exact because `K R = 0` for every design).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from .._spatial._solid_body_data import solid_body_data
from .element.h8 import H8
from .element.solid_base import AbstractSolidElement
from .material import SIMP
from .modal.auto import AutoModes
from .modal.base import AbstractModalSolver
from .modal.dense import DenseModes
from .solid_assembly import SolidFEModel, SolidOperator
from .solid_domain import SolidDesignDomain
from .solid_groups import PhysicalGroups
from .solid_layout import SolidReductionLayout, solid_reduction_layout
from .solid_modes import free_modes_dense

_DIRECTIONS = {"x": 0, "y": 1, "z": 2}


class SolidDesignedBody(eqx.Module):
    """One density-designed solid part (module docstring). Build it with [`solid_designed_body`][].

    **Fields:** `model` the [`SolidFEModel`][]; `domain` the [`SolidDesignDomain`][]; `material` the [`SIMP`][] law;
    `n_modes` retained eigenmodes (static); `fixed_dofs` the held degrees of freedom (static, sorted; empty: free-free
    modes, the six rigid-body modes removed); `markers` (static) the joint points, each a tuple of nodes (a point at
    their centroid, rotating with their rigid fit; see [`solid_body_data`][]); `modal_solver` (default
    [`AutoModes`][]) the modal solver of a supported part (module docstring).

    Every method is a pure function of `x` `(n_design,)`; pass the body as an argument of compiled functions.
    """

    model: SolidFEModel
    domain: SolidDesignDomain
    material: SIMP
    n_modes: int = eqx.field(static=True)
    fixed_dofs: tuple[int, ...] = eqx.field(static=True)
    markers: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    modal_solver: AbstractModalSolver = AutoModes()

    def __check_init__(self):
        if self.model.mesh != self.domain.mesh:
            raise ValueError("The solid FE model and the design domain must be built on the same mesh.")
        if not isinstance(self.modal_solver, AbstractModalSolver):
            raise TypeError(f"modal_solver must be DenseModes(), LanczosModes() or AutoModes(), got "
                            f"{self.modal_solver!r}.")
        free = self.model.n_dof - len(self.fixed_dofs) - (0 if self.fixed_dofs else 6)
        if not isinstance(self.n_modes, int) or not 0 < self.n_modes < free:
            raise ValueError(f"n_modes={self.n_modes} must be a positive int below the {free} free degrees of freedom "
                             "(less the six rigid-body modes of a free part).")

    @property
    def mesh(self):
        return self.model.mesh

    @property
    def layout(self) -> SolidReductionLayout:
        """The held (supports) and interior degrees of freedom of the modal problem; a `ValueError` where the supports
        leave a rigid motion free (checked when the modes are first computed)."""
        return solid_reduction_layout(self.model.mesh, self.fixed_dofs)

    @property
    def n_design(self) -> int:
        return self.domain.n_design

    def initial_design(self, value: float = 0.5):
        """A uniform design `x_e = value`, `(n_design,)`."""
        if not self.material.x_min <= float(value) <= 1.0:
            raise ValueError(f"Design value {value} lies outside [x_min, 1] = [{self.material.x_min}, 1].")
        return self.domain.initial_design(value)

    def check(self, x, body: str | None = None):
        """Validate a design: shape at trace time; NaN and the bounds `[x_min, 1]` at run time."""
        return self.domain.check(x, self.material.x_min, body)

    def element_values(self, x):
        """`(E_e, rho_e)`, `(n_elements,)` each: SIMP of `x` on design elements, of 1 / `x_min` on passive ones."""
        xe = self.domain.element_densities(self.check(x), self.material.x_min)
        return self.material.youngs(xe), self.material.densities(xe)

    def matrices(self, x) -> tuple[SolidOperator, SolidOperator]:
        """Matrix-free `(K(x), M(x))` of the whole part (no supports removed)."""
        youngs, densities = self.element_values(x)
        return self.model.stiffness(youngs), self.model.mass(densities)

    def eigenpairs(self, x):
        """`(lam, Phi)`: the `n_modes` lowest `omega^2` `(n_modes,)` and M-orthonormal modes `(n_dof, n_modes)`,
        zero on the held degrees of freedom (with no supports: the lowest elastic modes of the free part)."""
        youngs, densities = self.element_values(x)
        solver = self.modal_solver.choose(self.model) if isinstance(self.modal_solver, AutoModes) else self.modal_solver
        if not self.fixed_dofs and isinstance(solver, DenseModes):
            return free_modes_dense(self.model, youngs, densities, self.n_modes)
        return solver.solve(self.model, youngs, densities, self.layout, self.n_modes)

    def frequencies(self, x):
        """Eigenfrequencies of the retained modes in Hz, `(n_modes,)`."""
        return jnp.sqrt(self.eigenpairs(x)[0]) / (2 * jnp.pi)

    def body_data(self, x) -> SpatialFlexibleBodyData:
        """The spatial body data of the part at design `x` ([`solid_body_data`][] of `K(x)`, `M(x)`, `Phi(x)`)."""
        k, m = self.matrices(x)
        _, modes = self.eigenpairs(x)
        return solid_body_data(self.mesh.nodes, k, m, modes, self.markers, elements=self.mesh.elements)


def _supports(groups: PhysicalGroups, supports) -> tuple[int, ...]:
    if not isinstance(supports, dict):
        raise TypeError(f"supports must be a dict {{group name: directions}}, e.g. {{'big_bore': 'xyz'}}, got "
                        f"{supports!r}.")
    fixed = []
    for name, directions in supports.items():
        if not isinstance(directions, str) or not directions or set(directions) - set(_DIRECTIONS):
            raise ValueError(f"supports[{name!r}] must name the held directions as a string of 'x', 'y', 'z' (e.g. "
                             f"'xyz' or 'yz'), got {directions!r}.")
        nodes = np.asarray(groups.nodes(name))
        fixed.extend(int(3 * n + _DIRECTIONS[d]) for n in nodes for d in set(directions))
    return tuple(sorted(set(fixed)))


def solid_designed_body(groups: PhysicalGroups, n_modes: int, *, markers: tuple[str, ...], supports=None,
                        solid: tuple[str, ...] = (), void: tuple[str, ...] = (),
                        element: AbstractSolidElement = H8(), poisson: float = 0.3,
                        material: SIMP = SIMP(), modal_solver: AbstractModalSolver = AutoModes()) -> SolidDesignedBody:
    """A density-designed solid part from a mesh with named physical groups.

    **Arguments:**
    - `groups`: the mesh and its [`PhysicalGroups`][] (e.g. [`read_solid_groups`][]`("part.msh")`).
    - `n_modes`: retained eigenmodes.
    - `markers`: names of the groups (e.g. bore surfaces) whose nodes are the joint points, in marker order.
    - `supports`: `{group name: held directions}`, e.g. `{"big_bore": "xyz", "small_bore": "yz"}`: the directions
      held at every node of the group while computing the modes (the reference conditions of the floating frame:
      they must remove the six rigid-body motions). `None` (default): free-free modes.
    - `solid`, `void`: names of physical volumes that are passive solid or passive void (no design variable).
    - `element`: [`H8`][] (default), [`H11`][] or [`Tet10`][] (matching the mesh); `poisson`; `material`.
    - `modal_solver`: [`AutoModes`][] (default: sparse [`LanczosModes`][] above 1,000 degrees of freedom),
      [`DenseModes`][] or [`LanczosModes`][] (with supports or free).

    **Returns:** a [`SolidDesignedBody`][].

    **Raises** `ValueError` for an unknown group name (listing the mesh's groups), a group of the wrong dimension, an
    interface face not on the part's surface, and an unknown direction.
    """
    if not isinstance(groups, PhysicalGroups):
        raise TypeError(f"groups must be PhysicalGroups (fj.read_solid_groups), got {type(groups).__name__}.")
    if isinstance(markers, str) or not isinstance(markers, tuple) or not markers:
        raise ValueError(f"markers must be a non-empty tuple of group names, e.g. ('big_bore', 'small_bore'), got "
                         f"{markers!r}.")
    marker_nodes = tuple(groups.nodes(name) for name in markers)
    fixed = () if supports is None else _supports(groups, supports)
    domain = SolidDesignDomain.from_groups(groups, solid=solid, void=void)
    model = SolidFEModel(groups.mesh, element, poisson)
    return SolidDesignedBody(model, domain, material, n_modes, fixed, marker_nodes, modal_solver)
