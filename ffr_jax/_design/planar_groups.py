"""Named regions of a planar quadrilateral mesh: the physical groups of a gmsh mesh (through `meshio`).

A designer names the parts of a planar part in gmsh: `Physical Surface("rims") = {...}` for passive regions or the
design region, `Physical Curve("bore_A") = {...}` for the edge of a bore (an interface, a marker, a clamped set).
[`PlanarGroups`][] resolves a name to the elements of a surface group (an element mask for
[`DesignDomain.from_groups`][]) or the boundary edges and nodes of a curve group, in the numbering of the
[`QuadMesh`][] that [`from_meshio`][] builds: no searching of nodes by distance. Unknown names, a group of the wrong
dimension and a curve off the mesh's boundary are `ValueError`s naming the group and the fix.
"""

import numpy as np

from .mesh import QuadMesh, _format_ids, from_meshio
from .named_groups import NamedGroups, collected, physical_names, point_renumbering, read_meshio, tagged_cells

_LINES = ("line", "line3")


def boundary_edges(mesh: QuadMesh) -> np.ndarray:
    """The edges of `mesh` that belong to one element only (its boundary), `(n_edges, 2)` sorted node pairs."""
    edges = np.stack([mesh.elements, np.roll(mesh.elements, -1, axis=1)], axis=-1).reshape(-1, 2)
    keys, counts = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    return keys[counts == 1]


class PlanarGroups(NamedGroups):
    """The physical groups of a planar quadrilateral mesh, by name (see the module docstring). Build it with
    [`read_planar_groups`][], [`planar_groups_from_meshio`][] or [`link_profile`][ffr_jax.link_profile].

    **Attributes:** `mesh`, the [`QuadMesh`][]; `dimensions`, `{name: 0 (point), 1 (curve) or 2 (surface)}`.

    **Methods:** `elements(name)` / `mask(name)` of a surface; `edges(name)` of a curve (checked to lie on the
    boundary); `nodes(name)` of any group; `names(dimension=None)`.
    """

    __slots__ = ("_elements", "_edges", "_points")
    _KINDS = {0: "point", 1: "curve", 2: "surface"}
    _WANTS = {1: "a physical curve (boundary edges)", 2: "a physical surface (elements)"}
    _DEFINE = 'Physical Surface("{name}") = {{...}}; or Physical Curve'

    def __init__(self, mesh: QuadMesh, dimensions: dict, elements: dict, edges: dict, points: dict):
        if not isinstance(mesh, QuadMesh):
            raise TypeError(f"mesh must be a QuadMesh, got {type(mesh).__name__}.")
        self.mesh, self.dimensions = mesh, dict(dimensions)
        self._elements, self._edges, self._points = elements, edges, points

    def elements(self, name: str) -> np.ndarray:
        """The element indices of the physical surface `name` (a passive region, the design region), sorted."""
        self._check(name, 2)
        return self._nonempty(name, self._elements[name])

    def mask(self, name: str) -> np.ndarray:
        """The boolean element mask `(n_elements,)` of the physical surface `name`."""
        mask = np.zeros(self.mesh.n_elements, dtype=bool)
        mask[self.elements(name)] = True
        return mask

    def edges(self, name: str) -> np.ndarray:
        """The edges of the physical curve `name` as node pairs `(n_edges, 2)`, each checked to be an edge on the
        boundary of the mesh (a bore, a clamped or loaded edge)."""
        self._check(name, 1)
        edges = self._nonempty(name, self._edges[name])
        boundary = {tuple(k) for k in boundary_edges(self.mesh)}
        off = np.flatnonzero([tuple(k) not in boundary for k in np.sort(edges, axis=1)])
        if off.size:
            raise ValueError(
                f"{off.size} of the {len(edges)} edges of the physical curve {name!r} are not on the boundary of the "
                f"mesh (edges {_format_ids(off)}: between two elements, or not an edge of any element). An "
                "interface, clamped or loaded edge must be part of the part's boundary: in gmsh, put the bore's or "
                "edge's boundary curves in the group, not an inner curve (e.g. between a rim and the design region), "
                "and mesh the surfaces and the group together.")
        return edges

    def nodes(self, name: str) -> tuple[int, ...]:
        """The nodes of the physical group `name`, sorted: a curve's (its edges checked as in `edges`: e.g. the
        node set of a bore as an interface or marker, or the nodes to hold), a surface's or a point's."""
        self._check(name)
        dimension = self.dimensions[name]
        if dimension == 1:
            nodes = self.edges(name).ravel()
        elif dimension == 2:
            nodes = self.mesh.elements[self.elements(name)].ravel()
        else:
            nodes = self._nonempty(name, self._points[name])
        return tuple(int(n) for n in np.unique(nodes))


def planar_groups_from_meshio(mesh, min_jacobian_ratio: float | None = None) -> PlanarGroups:
    """The [`PlanarGroups`][] of a `meshio.Mesh` with gmsh physical groups (`field_data` names and `gmsh:physical`
    cell tags), on its quadrilateral mesh ([`from_meshio`][], whose numbering the groups use).

    `min_jacobian_ratio`: passed to the [`QuadMesh`][] (default its own, 0.05).

    **Returns:** a [`PlanarGroups`][]. A named group of dimension 3 or a curve through a node that no quadrilateral
    uses is a `ValueError`.
    """
    blocks = [np.asarray(b.data) for b in mesh.cells if b.type == "quad"]
    if blocks:
        _, counts = np.unique(np.sort(np.concatenate(blocks), axis=1), axis=0, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"The mesh repeats {np.count_nonzero(counts > 1)} quadrilaterals: a gmsh 2.2 file holds "
                             "an element once for each physical group of its surface. Give each surface one physical "
                             "group (e.g. \"rims\" or \"rim_A\", not both).")
    quad_mesh = from_meshio(mesh, min_jacobian_ratio=min_jacobian_ratio)
    named = physical_names(mesh, "Physical Surface/Curve")
    volumes = sorted(name for name, _, dim in named if dim == 3)
    if volumes:
        raise ValueError(f"The physical groups {volumes} are volumes: a planar mesh has surfaces, curves and points; "
                         "read a solid part with read_solid_groups.")
    renumber = point_renumbering(mesh, "quad")  # as from_meshio: the points some quad uses, in their order
    elements, edges, points = {}, {}, {}
    for name, dim, kind, cells, rows in tagged_cells(mesh, named, "quad"):
        if kind == "quad" and dim == 2:
            elements.setdefault(name, []).append(rows)
        elif kind in _LINES and dim == 1:
            edges.setdefault(name, []).append(renumber[cells[:, :2]])
        elif kind == "vertex" and dim == 0:
            points.setdefault(name, []).append(renumber[cells.ravel()])
    dimensions = {name: dim for name, _, dim in named}
    empty = np.zeros(0, dtype=np.int64)
    elements = collected(elements, [n for n, d in dimensions.items() if d == 2],
                         lambda v: np.sort(np.concatenate(v)), empty)
    edges = collected(edges, [n for n, d in dimensions.items() if d == 1], lambda v: np.concatenate(v, axis=0),
                      np.zeros((0, 2), np.int64))
    points = collected(points, [n for n, d in dimensions.items() if d == 0], np.concatenate, empty)
    for name, found in (*edges.items(), *points.items()):
        if np.any(found < 0):
            raise ValueError(f"The physical group {name!r} holds nodes that no quadrilateral uses (a curve or point "
                             "off the meshed surfaces): put only curves and points of the meshed part in it.")
    return PlanarGroups(quad_mesh, dimensions, elements, edges, points)


def read_planar_groups(path, min_jacobian_ratio: float | None = None) -> PlanarGroups:
    """Read a gmsh mesh file of a planar part with named physical groups: its [`QuadMesh`][] and [`PlanarGroups`][].

    The passive regions and the design region are physical surfaces, the bores and clamped edges physical curves;
    build the design domain with [`DesignDomain.from_groups`][] and take interfaces, clamped sets and markers as
    `groups.nodes(name)`.

    **Arguments:** `path`, a `.msh` file (gmsh 2.2 or 4.1) of linear quadrilaterals; `min_jacobian_ratio`, passed
    to the [`QuadMesh`][] (default its own, 0.05).

    **Returns:** a [`PlanarGroups`][] (`.mesh` the [`QuadMesh`][], as [`read_mesh`][] reads it).
    """
    mesh = read_meshio(path, "read_planar_groups", "give a gmsh .msh file with named physical groups.")
    return planar_groups_from_meshio(mesh, min_jacobian_ratio)
