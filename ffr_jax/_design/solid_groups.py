"""Named regions of a solid mesh: the physical groups of a gmsh mesh (through `meshio`).

A designer names the bores, bolt faces and passive volumes of a part in gmsh (`Physical Surface("bore") = {...}`,
`Physical Volume("hub") = {...}`); the written mesh holds each group's cells tagged (`gmsh:physical` cell data) and
the names in its `field_data` (`{name: [tag, dimension]}`). [`PhysicalGroups`][] resolves a name to the elements of
a volume group, the faces of a surface group (checked to lie on the mesh's surface: an interface is where the part
meets a joint) or the nodes of either, in the numbering of the [`SolidMesh`][] that `solid_from_meshio` builds —
no searching of nodes by distance. Unknown names, a group of the wrong dimension and faces inside the part are
`ValueError`s naming the group and the fix.
"""

import numpy as np

from .element.solid_base import _format_ids
from .named_groups import NamedGroups, collected, physical_names, point_renumbering, read_meshio, tagged_cells
from .solid_mesh import SolidMesh, _SOLID_CELLS, solid_from_meshio

# Corner-node faces of each solid cell (VTK/meshio node order): a face is the sorted tuple of its corners.
_CELL_FACES = {
    "hexahedron": ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
    "tetra10": ((0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)),
}
# Corners of the surface cells gmsh writes for a physical surface.
_FACE_CORNERS = {"triangle": 3, "triangle6": 3, "quad": 4, "quad8": 4, "quad9": 4}


def _face_keys(faces: np.ndarray) -> np.ndarray:
    return np.sort(faces, axis=1)


def boundary_faces(mesh: SolidMesh) -> np.ndarray:
    """The faces of `mesh` that belong to one element only (its surface), `(n_faces, corners)` sorted corner
    nodes."""
    faces = np.concatenate([mesh.elements[:, list(f)] for f in _CELL_FACES[mesh.cell_type]], axis=0)
    keys, counts = np.unique(_face_keys(faces), axis=0, return_counts=True)
    return keys[counts == 1]


class PhysicalGroups(NamedGroups):
    """The physical groups of a solid mesh, by name (see the module docstring). Build it with
    [`read_solid_groups`][] or `solid_groups_from_meshio`.

    **Attributes:** `mesh`, the [`SolidMesh`][]; `dimensions`, `{name: 2 (surface) or 3 (volume)}`.
    """

    __slots__ = ("_elements", "_faces", "_face_nodes")
    _KINDS = {2: "surface", 3: "volume"}
    _WANTS = {2: "a physical surface (faces)", 3: "a physical volume (elements)"}
    _DEFINE = 'Physical Surface("{name}") = {{...}}; or Physical Volume'

    def __init__(self, mesh: SolidMesh, dimensions: dict, elements: dict, faces: dict, face_nodes: dict):
        self.mesh, self.dimensions = mesh, dict(dimensions)
        self._elements, self._faces, self._face_nodes = elements, faces, face_nodes

    def elements(self, name: str) -> np.ndarray:
        """The element indices of the physical volume `name` (e.g. a passive region), sorted."""
        self._check(name, 3)
        return self._nonempty(name, self._elements[name])

    def faces(self, name: str) -> np.ndarray:
        """The faces of the physical surface `name` as corner-node tuples `(n_faces, 3 or 4)`, each checked to be a
        face on the surface of the mesh (an interface, a clamped face, a loaded face)."""
        self._check(name, 2)
        faces = self._nonempty(name, self._faces[name])
        boundary = {tuple(k) for k in boundary_faces(self.mesh)}
        off = np.flatnonzero([tuple(k) not in boundary for k in _face_keys(faces)])
        if off.size:
            raise ValueError(
                f"{off.size} of the {len(faces)} faces of the physical surface {name!r} are not on the surface of the "
                f"mesh (faces {_format_ids(off)}: inside the part, between two elements, or not a face of any "
                "element). An interface, clamped or loaded face must be part of the solid's boundary: in gmsh, put "
                "the bore's or face's boundary surfaces in the group, not an inner (embedded) surface, and mesh the "
                "volume and the group together.")
        return faces

    def nodes(self, name: str) -> tuple[int, ...]:
        """The nodes of the physical group `name` (a surface's faces are checked as in `faces`), sorted: e.g. the
        node set of a bore as a marker, or the nodes to hold."""
        self._check(name)
        if self.dimensions[name] == 2:
            self.faces(name)
            return tuple(int(n) for n in np.unique(self._face_nodes[name]))
        return tuple(int(n) for n in np.unique(self.mesh.elements[self.elements(name)]))


def solid_groups_from_meshio(mesh, orientation: str = "refuse",
                             min_jacobian_ratio: float | None = None) -> PhysicalGroups:
    """The [`PhysicalGroups`][] of a `meshio.Mesh` with gmsh physical groups (`field_data` names and
    `gmsh:physical` cell tags), on its solid mesh (`solid_from_meshio`; `min_jacobian_ratio` passed to it)."""
    solid = solid_from_meshio(mesh, orientation, min_jacobian_ratio)
    named = physical_names(mesh, "Physical Surface/Volume")
    solid_type = next(b.type for b in mesh.cells if b.type in _SOLID_CELLS)
    renumber = point_renumbering(mesh, solid_type)
    elements, faces, face_nodes = {}, {}, {}
    for name, dim, kind, cells, rows in tagged_cells(mesh, named, solid_type):
        if kind == solid_type and dim == 3:
            elements.setdefault(name, []).append(rows)
        elif kind in _FACE_CORNERS and dim == 2:
            faces.setdefault(name, []).append(renumber[cells[:, :_FACE_CORNERS[kind]]])
            face_nodes.setdefault(name, []).append(renumber[cells].ravel())
    dimensions = {name: dim for name, _, dim in named}
    volumes = [n for n, d in dimensions.items() if d == 3]
    surfaces = [n for n, d in dimensions.items() if d == 2]
    empty = np.zeros(0, dtype=np.int64)
    return PhysicalGroups(solid, dimensions,
                          collected(elements, volumes, lambda v: np.sort(np.concatenate(v)), empty),
                          collected(faces, surfaces, lambda v: np.concatenate(v, axis=0), np.zeros((0, 3), np.int64)),
                          collected(face_nodes, surfaces, np.concatenate, empty))


def read_solid_groups(path, orientation: str = "refuse", min_jacobian_ratio: float | None = None) -> PhysicalGroups:
    """Read a gmsh mesh file with named physical groups: its solid mesh and its [`PhysicalGroups`][].

    **Returns:** a [`PhysicalGroups`][] (`.mesh` the [`SolidMesh`][], as [`read_solid_mesh`][] reads it).
    """
    mesh = read_meshio(path, "read_solid_groups", "give a gmsh .msh file with named physical groups.")
    return solid_groups_from_meshio(mesh, orientation, min_jacobian_ratio)
