"""What the planar and the solid physical groups share: names checked against the file's groups, the names and
tags of a gmsh mesh read through `meshio`, reading the file, and passive-region masks by name.

A gmsh mesh file holds each physical group's cells tagged (`gmsh:physical` cell data) and the names in its
`field_data` (`{name: [tag, dimension]}`). [`PlanarGroups`][] (quadrilateral parts) and [`PhysicalGroups`][] (solid
parts) resolve the names on their mesh; both refuse an unknown name or a group of the wrong dimension with the
groups the file has and how to name one in gmsh.
"""

import pathlib

import numpy as np

TAG = "gmsh:physical"


class NamedGroups:
    """Base of the physical groups of a mesh: `mesh`, `dimensions` (`{name: dimension}`) and the name checks.

    A subclass sets `_KINDS` (`{dimension: "surface", ...}`), `_WANTS` (`{dimension: what a method needs}`) and
    `_DEFINE` (how to define a group named `{name}` in gmsh, for the messages).
    """

    __slots__ = ("mesh", "dimensions")
    _KINDS: dict = {}
    _WANTS: dict = {}
    _DEFINE: str = ""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._listing()}, mesh={self.mesh!r})"

    def _listing(self) -> str:
        kinds = self._KINDS
        return ", ".join(f"{n!r} ({kinds.get(d, f'dimension {d}')})" for n, d in sorted(self.dimensions.items()))

    def _check(self, name, dimension: int | None = None) -> None:
        if not isinstance(name, str):
            raise TypeError(f"A physical group is named by a str, got {name!r}.")
        if name not in self.dimensions:
            raise ValueError(f"This mesh has no physical group named {name!r}; its groups are: "
                             f"{self._listing() or 'none'}. Check the spelling, or name the group in gmsh "
                             f"({self._DEFINE.format(name=name)}) before meshing.")
        if dimension is not None and self.dimensions[name] != dimension:
            raise ValueError(f"The physical group {name!r} has dimension {self.dimensions[name]}, but this needs "
                             f"{self._WANTS[dimension]}; its groups are: {self._listing()}.")

    def _nonempty(self, name: str, found: np.ndarray) -> np.ndarray:
        """`found` (the cells of the group `name`), or a `ValueError` when the group has none in this mesh."""
        if len(found) == 0:
            raise ValueError(f"The physical group {name!r} has no cells in this mesh. meshio keeps one physical tag "
                             "per element of a gmsh 4.1 file, so a group whose surfaces or curves belong to another "
                             "group as well reads empty: give each surface and curve one physical group (e.g. "
                             "\"rims\" or \"rim_A\", not both), or put the group's own entities in it.")
        return found

    def names(self, dimension: int | None = None) -> tuple[str, ...]:
        """The group names, sorted; only those of `dimension` if given."""
        return tuple(sorted(n for n, d in self.dimensions.items() if dimension is None or d == dimension))


def physical_names(mesh, define: str) -> tuple[tuple[str, int, int], ...]:
    """`(name, tag, dimension)` of each named physical group of a `meshio.Mesh`, or a `ValueError` when it has none
    (`define` says how to define them in gmsh)."""
    field = getattr(mesh, "field_data", None) or {}
    if not field or TAG not in mesh.cell_data:
        raise ValueError("This mesh holds no named physical groups (no field_data names or no 'gmsh:physical' cell "
                         f"tags): define them in gmsh ({define} with a name) and write the mesh as a .msh file that "
                         "keeps them (gmsh itself, or meshio with file_format='gmsh22').")
    return tuple((name, int(v[0]), int(v[1])) for name, v in ((n, np.asarray(v).ravel()[:2]) for n, v in field.items()))


def read_meshio(path, who: str, advice: str):
    """`meshio.read(path)` with a `FileNotFoundError` for a missing file and a `ValueError` (`who`: the caller,
    `advice`: what to give instead) for one meshio cannot read."""
    import meshio

    if not pathlib.Path(path).is_file():
        raise FileNotFoundError(f"{who}: no mesh file at {str(path)!r}.")
    try:
        return meshio.read(path)
    except (Exception, SystemExit) as err:  # meshio exits (SystemExit) on some unreadable files
        raise ValueError(f"{who}: meshio could not read {str(path)!r} ({type(err).__name__}: {err}); "
                         f"{advice}") from None


def masks_by_name(groups, n_elements: int, solid=(), void=()) -> dict[str, np.ndarray]:
    """Boolean element masks `{"solid": ..., "void": ...}` `(n_elements,)` of the element groups named in `solid`
    and `void` (a name or a tuple of names), through `groups.elements(name)`."""
    masks = {}
    for label, names in (("solid", solid), ("void", void)):
        if isinstance(names, str):
            names = (names,)
        mask = np.zeros(n_elements, dtype=bool)
        for name in names:
            mask[groups.elements(name)] = True
        masks[label] = mask
    return masks


def point_renumbering(mesh, cell_type: str) -> np.ndarray:
    """Point index -> node index `(n_points,)` of the mesh a reader builds from the `cell_type` cells of a
    `meshio.Mesh` (the points those cells use, in their order; -1 for the others)."""
    used = np.unique(np.concatenate([np.asarray(b.data).ravel() for b in mesh.cells if b.type == cell_type]))
    renumber = np.full(np.asarray(mesh.points).shape[0], -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    return renumber


def tagged_cells(mesh, named, cell_type: str):
    """For each cell block of a `meshio.Mesh` and each named group `(name, tag, dimension)` of `named`: `(name,
    dimension, block type, the block's cells in the group, their indices among all cells of `cell_type`)`."""
    offset = 0
    for block, tags in zip(mesh.cells, mesh.cell_data[TAG]):
        tags, data = np.asarray(tags).ravel(), np.asarray(block.data)
        for name, tag, dim in named:
            rows = np.flatnonzero(tags == tag)
            yield name, dim, block.type, data[rows], offset + rows
        if block.type == cell_type:
            offset += len(data)


def collected(parts: dict, names, join, empty) -> dict:
    """`{name: join(parts[name])}` for each of `names`, `empty` for a name without parts (a named group without
    cells of this mesh)."""
    return {name: join(parts[name]) if name in parts else empty for name in names}
