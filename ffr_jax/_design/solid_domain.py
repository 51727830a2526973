"""Element roles of a solid mesh (design / passive solid / passive void), passive regions named by physical groups."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .domain import checked_design, checked_roles, element_densities, roles_from_masks
from .named_groups import masks_by_name
from .solid_groups import PhysicalGroups
from .solid_mesh import SolidMesh


class SolidDesignDomain(eqx.Module):
    """Which elements of a solid mesh carry a design variable, and which are passive solid or void.

    The 3-D counterpart of [`DesignDomain`][]: the design vector `x` holds one density per design element, in
    ascending element order; passive solid elements have `x_e = 1`, passive void ones `x_e = x_min`, and neither
    carries a design variable (no gradient reaches them). Build it with [`SolidDesignDomain.from_groups`][] (passive
    regions by the names of the mesh's physical volumes: no searching of elements by position) or from masks.

    **Fields:** `mesh` (static), `roles` `(n_elements,)` (`DESIGN = 0`, `SOLID = 1`, `VOID = 2`),
    `design_elements` `(n_design,)` the element of each design variable, `n_design` (static).
    """

    mesh: SolidMesh = eqx.field(static=True)
    roles: Int[Array, " n_elements"]
    design_elements: Int[Array, " n_design"]
    n_design: int = eqx.field(static=True)

    def __init__(self, mesh: SolidMesh, roles=None):
        if not isinstance(mesh, SolidMesh):
            raise TypeError(f"mesh must be a SolidMesh (box_grid, read_solid_mesh), got {type(mesh).__name__}.")
        roles, design = checked_roles(mesh.n_elements, roles,
                                      "The solid design domain has no design element (every element is passive).")
        self.mesh = mesh
        self.roles = jnp.asarray(roles, dtype=jnp.int8)
        self.design_elements = jnp.asarray(design, dtype=jnp.int32)
        self.n_design = int(design.size)

    @classmethod
    def from_masks(cls, mesh: SolidMesh, solid=None, void=None) -> "SolidDesignDomain":
        """Roles from boolean element masks `(n_elements,)`: `solid` and `void` (disjoint), the rest design."""
        return cls(mesh, roles_from_masks(mesh.n_elements, solid, void))

    @classmethod
    def from_groups(cls, groups: PhysicalGroups, solid: str | tuple[str, ...] = (),
                    void: str | tuple[str, ...] = ()) -> "SolidDesignDomain":
        """Passive regions by name: the elements of the physical volumes `solid` (a name or a tuple of names) are
        passive solid, those of `void` passive void, the rest design. An unknown name or a surface group is a
        `ValueError` naming the groups."""
        if not isinstance(groups, PhysicalGroups):
            raise TypeError(f"groups must be PhysicalGroups (fj.read_solid_groups), got {type(groups).__name__}.")
        return cls.from_masks(groups.mesh, **masks_by_name(groups, groups.mesh.n_elements, solid, void))

    def design_centroids(self) -> np.ndarray:
        """Centroids `(n_design, 3)` of the design elements (mean of their nodes), in design order."""
        return self.mesh.element_coordinates().mean(axis=1)[np.asarray(self.design_elements)]

    def design_areas(self) -> np.ndarray:
        """Volumes `(n_design,)` of the design elements (the volume weights; named as the planar domain's areas so
        that `fj.DensityFilter` and `fj.VolumeConstraint` take either), in design order."""
        return self.mesh.element_volumes()[np.asarray(self.design_elements)]

    def initial_design(self, value: float = 0.5) -> Float[Array, " n_design"]:
        """A uniform design `x_e = value`."""
        return jnp.full((self.n_design,), float(value))

    def check(self, x, x_min: float, body: str | None = None) -> Float[Array, " n_design"]:
        """Validate a design as [`DesignDomain.check`][]: dtype and shape at trace time, NaN, inf and the bounds
        `[x_min, 1]` at once when concrete, else at run time; a [`DesignError`][] otherwise."""
        return checked_design(self, x, x_min, body)

    def element_densities(self, x, x_min: float) -> Float[Array, " n_elements"]:
        """All element densities `(n_elements,)`: `x` on design elements, 1 on solid, `x_min` on void."""
        return element_densities(self, x, x_min)
