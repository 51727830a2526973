"""Element roles over a mesh (design / passive solid / passive void) and the design-vector layout."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._checks import DESIGN_SLACK, design_array, design_values, is_traced
from .._errors import DesignError, error_if
from .mesh import QuadMesh, StructuredGrid, _format_ids
from .named_groups import masks_by_name
from .planar_groups import PlanarGroups

DESIGN, SOLID, VOID = 0, 1, 2
_ROLE_NAMES = {DESIGN: "design", SOLID: "passive solid", VOID: "passive void"}


def checked_roles(n_elements: int, roles, empty: str) -> tuple[np.ndarray, np.ndarray]:
    """`(roles, design elements)` of a role array `(n_elements,)` (`None`: all design), or a `ValueError`; `empty`
    is the message for a domain without a design element. Shared by [`DesignDomain`][] and the solid domain."""
    roles = np.zeros(n_elements, dtype=np.int8) if roles is None else np.asarray(roles)
    if roles.shape != (n_elements,):
        raise ValueError(f"roles must have shape ({n_elements},) (one per element), got {roles.shape}.")
    bad = np.flatnonzero(~np.isin(roles, list(_ROLE_NAMES)))
    if bad.size:
        raise ValueError(f"roles must be DESIGN (0), SOLID (1) or VOID (2); elements {_format_ids(bad)} are not.")
    design = np.flatnonzero(roles == DESIGN)
    if design.size == 0:
        raise ValueError(empty)
    return roles, design


def roles_from_masks(n_elements: int, solid=None, void=None) -> np.ndarray:
    """Roles from boolean element masks `(n_elements,)`: `solid` and `void` (disjoint), the rest design."""
    roles = np.zeros(n_elements, dtype=np.int8)
    for name, mask, role in (("solid", solid, SOLID), ("void", void, VOID)):
        if mask is None:
            continue
        mask = np.asarray(mask)
        if mask.shape != (n_elements,) or mask.dtype != bool:
            raise ValueError(f"The {name} mask must be a boolean array of shape ({n_elements},), "
                             f"got {mask.dtype} {mask.shape}.")
        clash = np.flatnonzero(mask & (roles != DESIGN))
        if clash.size:
            raise ValueError(f"Elements {_format_ids(clash)} are marked both solid and void.")
        roles[mask] = role
    return roles


def checked_design(domain, x, x_min: float, body: str | None = None) -> Float[Array, " n_design"]:
    """[`DesignDomain.check`][] for any domain with `n_design` and `mesh.n_elements` (the planar and solid ones)."""
    of_body = "" if body is None else f" for body {body!r}"
    x = design_array(x, of_body)
    if x.shape != (domain.n_design,):
        raise DesignError(
            f"Design vector has shape {x.shape}, expected ({domain.n_design},){of_body}: one density per design "
            f"element ({domain.mesh.n_elements} elements, {domain.mesh.n_elements - domain.n_design} passive). "
            "Use initial_design(value) for a valid vector."
        )
    if not is_traced(x):
        design_values(x, x_min, of_body)
        return x
    x = error_if(x, ~jnp.all(jnp.isfinite(x)), f"Design vector contains NaN or inf{of_body}; every density must "
                 f"be a finite number in [x_min, 1] = [{x_min}, 1].", DesignError)
    return error_if(
        x, jnp.any((x < x_min - DESIGN_SLACK) | (x > 1.0 + DESIGN_SLACK)),
        f"Design densities must lie in [x_min, 1] = [{x_min}, 1]{of_body}; clip or project the design first.",
        DesignError,
    )


def element_densities(domain, x, x_min: float) -> Float[Array, " n_elements"]:
    """All element densities `(n_elements,)` of a domain: `x` on design elements, 1 on solid, `x_min` on void."""
    passive = jnp.where(domain.roles == SOLID, 1.0, jnp.where(domain.roles == VOID, x_min, 0.0)).astype(x.dtype)
    return passive.at[domain.design_elements].set(x)


class DesignDomain(eqx.Module):
    """Which elements of a mesh carry a design variable, and which are passive solid or void.

    The design vector `x` holds one density per design element, in ascending element order.
    Passive solid elements have `x_e = 1` and passive void elements `x_e = x_min` (SIMP's lower
    bound); neither carries a design variable, so no gradient reaches them.

    - `mesh`: the mesh (static).
    - `roles`: `(n_elements,)` int8, `DESIGN = 0`, `SOLID = 1`, `VOID = 2`.
    - `design_elements`: `(n_design,)` element index of each design variable (a pytree leaf, so
      that a compiled program receives it as an input rather than as a constant).

    Build it with [`DesignDomain.from_masks`][], [`DesignDomain.from_groups`][] (passive regions by the names of
    the mesh's physical surfaces) or from a role array.
    """

    mesh: QuadMesh = eqx.field(static=True)
    roles: Int[Array, " n_elements"]
    design_elements: Int[Array, " n_design"]
    n_design: int = eqx.field(static=True)

    def __init__(self, mesh: QuadMesh, roles=None):
        if not isinstance(mesh, QuadMesh):
            raise TypeError(f"mesh must be a QuadMesh, got {type(mesh).__name__}.")
        roles, design = checked_roles(mesh.n_elements, roles, "The domain has no design element (every element is passive).")
        self.mesh = mesh
        self.roles = jnp.asarray(roles, dtype=jnp.int8)
        self.design_elements = jnp.asarray(design, dtype=jnp.int32)
        self.n_design = int(design.size)

    @classmethod
    def from_masks(cls, mesh: QuadMesh, solid=None, void=None) -> "DesignDomain":
        """Roles from boolean element masks `(n_elements,)`: `solid` and `void` (disjoint), the rest design."""
        return cls(mesh, roles_from_masks(mesh.n_elements, solid, void))

    @classmethod
    def from_groups(cls, groups: PlanarGroups, solid: str | tuple[str, ...] = (),
                    void: str | tuple[str, ...] = ()) -> "DesignDomain":
        """Passive regions by name: the elements of the physical surfaces `solid` (a name or a tuple of names) are
        passive solid, those of `void` passive void, the rest design (e.g. `solid="rims"` on a
        [`link_profile`][ffr_jax.link_profile] or a [`read_planar_groups`][] part). An unknown name or a curve group
        is a `ValueError` naming the groups."""
        if not isinstance(groups, PlanarGroups):
            raise TypeError(f"groups must be PlanarGroups (fj.read_planar_groups, fj.link_profile), got "
                            f"{type(groups).__name__}.")
        return cls.from_masks(groups.mesh, **masks_by_name(groups, groups.mesh.n_elements, solid, void))

    def role_array(self) -> np.ndarray:
        """The roles as a NumPy array (host side: filters, plots)."""
        return np.asarray(self.roles)

    def design_centroids(self) -> np.ndarray:
        """Centroids `(n_design, 2)` of the design elements, in design order."""
        return self.mesh.element_centroids()[np.asarray(self.design_elements)]

    def design_areas(self) -> np.ndarray:
        """Areas `(n_design,)` of the design elements (volume weights), in design order."""
        return self.mesh.element_areas()[np.asarray(self.design_elements)]

    def design_grid(self, values) -> np.ndarray:
        """A design-ordered vector `(n_design,)` as the rectangular block of grid elements it covers.

        Needs a `StructuredGrid` whose design elements fill whole rows and columns of a
        rectangle, e.g. the rod (`(ny, nx - 2)`: rows bottom to top, the solid end columns left out).

        **Returns:** `(rows, columns)` NumPy array.
        """
        mesh = self.mesh
        if not isinstance(mesh, StructuredGrid):
            raise ValueError("design_grid needs a structured grid (e.g. the rod); on another mesh, plot the values "
                             "over the elements (DesignDomain.design_elements gives each value's element).")
        elements = np.asarray(self.design_elements)
        rows, columns = np.unique(elements // mesh.nx), np.unique(elements % mesh.nx)
        if rows.size * columns.size != elements.size:
            raise ValueError("The design elements do not fill a rectangle of the grid; design_grid cannot arrange them.")
        values = np.asarray(values)
        if values.shape != (self.n_design,):
            raise ValueError(f"design_grid takes a vector of shape ({self.n_design},), got {values.shape}.")
        return values.reshape(rows.size, columns.size)

    def initial_design(self, value: float = 0.5) -> Float[Array, " n_design"]:
        """A uniform design `x_e = value`."""
        return jnp.full((self.n_design,), float(value))

    def check(self, x, x_min: float, body: str | None = None) -> Float[Array, " n_design"]:
        """Validate a design and return it as float64: dtype and shape at trace time, values (NaN,
        inf, bounds `[x_min, 1]`) at once when `x` is concrete, else at run time. Raises
        [`DesignError`][] (complex numbers refused; integers and float32 converted to float64).

        `body` (optional) names the body in the messages.
        """
        return checked_design(self, x, x_min, body)

    def element_densities(self, x, x_min: float) -> Float[Array, " n_elements"]:
        """All element densities `(n_elements,)`: `x` on design elements, 1 on solid, `x_min` on void."""
        return element_densities(self, x, x_min)
