"""Solid meshes: hexahedra or quadratic tetrahedra, checked, hashable by content.

The 3D counterpart of [`QuadMesh`][]: an immutable host object (NumPy arrays and a SHA-256
digest of its content), static configuration for `jax.jit`. One element type per mesh: 8-node
hexahedra (for [`H8`][] or [`H11`][]) or 10-node tetrahedra ([`Tet10`][]), nodes in the VTK
(meshio) order. Node `n` has the degrees of freedom `3 n`, `3 n + 1`, `3 n + 2` (`u_x, u_y, u_z`).

[`box_grid`][] builds a structured hexahedral grid of a box with an element mask; `solid_from_meshio`
and [`read_solid_mesh`][] take any solid mesh `meshio` reads (gmsh, VTU, Abaqus, ...).
"""

import hashlib

import numpy as np

from .element.h8 import H8, gauss_points_2x2x2, trilinear
from .element.solid_base import MIN_JACOBIAN_RATIO, AbstractSolidElement, _format_ids, jacobian_determinants
from .element.tet10 import Tet10, conical_product_points, quadratic_tet
from .named_groups import read_meshio

# The element whose shape checks a mesh of each cell type runs (any element of that type would do:
# the checks depend on the geometry only).
CELL_TYPES = {"hexahedron": H8(), "tetra10": Tet10()}
NODES_PER_CELL = {8: "hexahedron", 10: "tetra10"}
_VOLUME_RULES = {"hexahedron": (gauss_points_2x2x2, trilinear), "tetra10": (conical_product_points, quadratic_tet)}
# Nodes closer than this fraction of the shortest element edge count as duplicates.
DUPLICATE_NODE_TOLERANCE = 1e-9


class SolidMesh:
    """A mesh of 8-node hexahedra or 10-node tetrahedra, validated at construction and immutable.

    **Arguments:**
    - `nodes`: `(n_nodes, 3)` node coordinates (body frame).
    - `elements`: `(n_elements, 8)` (hexahedra) or `(n_elements, 10)` (quadratic tetrahedra) node
      indices, VTK order.
    - `orientation`: what to do with inverted elements (`det J < 0` everywhere: numbered in the
      mirrored order): `"refuse"` (default) raises, `"reorder"` mirrors their numbering.
    - `min_jacobian_ratio`: elements with `min det J / max det J` below this (default 0.05) are
      refused as badly shaped.

    **Raises** `ValueError` naming the element type and the offending indices for: wrong shapes or
    non-finite coordinates, node indices out of range, repeated nodes within an element, inverted,
    degenerate or badly shaped elements (and tetrahedral slivers), duplicate elements, unused nodes
    (rigid mechanisms) and duplicate nodes (the mesh would be cut there).
    """

    __slots__ = ("nodes", "elements", "cell_type", "digest", "_hash")

    def __init__(self, nodes, elements, *, orientation: str = "refuse",
                 min_jacobian_ratio: float = MIN_JACOBIAN_RATIO):
        if orientation not in ("reorder", "refuse"):
            raise ValueError(f"orientation must be 'reorder' or 'refuse', got {orientation!r}.")
        nodes = np.array(nodes, dtype=np.float64)
        elements = np.array(elements)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or nodes.shape[0] < 4:
            raise ValueError(f"nodes must have shape (n_nodes, 3) with n_nodes >= 4, got {nodes.shape}.")
        if not np.all(np.isfinite(nodes)):
            bad = np.flatnonzero(~np.all(np.isfinite(nodes), axis=1))
            raise ValueError(f"Node coordinates must be finite; nodes {_format_ids(bad)} are not.")
        if elements.ndim != 2 or elements.shape[1] not in NODES_PER_CELL or elements.shape[0] < 1:
            raise ValueError(f"elements must have shape (n_elements, 8) (hexahedra) or (n_elements, 10) (quadratic "
                             f"tetrahedra), got {elements.shape}.")
        if not np.issubdtype(elements.dtype, np.integer):
            if not np.all(elements == np.round(elements)):
                raise ValueError("elements must hold integer node indices.")
        elements = elements.astype(np.int64)
        cell_type = NODES_PER_CELL[elements.shape[1]]
        element = CELL_TYPES[cell_type]
        name = type(element).__name__
        n_nodes = nodes.shape[0]
        out = np.flatnonzero(np.any((elements < 0) | (elements >= n_nodes), axis=1))
        if out.size:
            raise ValueError(f"{name} elements {_format_ids(out)} refer to node indices outside [0, {n_nodes}); "
                             "connectivity must index the rows of nodes (0-based).")
        sorted_nodes = np.sort(elements, axis=1)
        repeated = np.flatnonzero(np.any(np.diff(sorted_nodes, axis=1) == 0, axis=1))
        if repeated.size:
            raise ValueError(f"{name} elements {_format_ids(repeated)} repeat a node (collapsed elements, e.g. "
                             "prisms or pyramids written as hexahedra); mesh with true hexahedra or tetrahedra.")
        if orientation == "reorder":
            det = element.jacobian_samples(nodes[elements])
            mirrored = np.all(det < 0.0, axis=1)
            elements[mirrored] = elements[mirrored][:, element.reordered()]
        element.check(nodes[elements], min_jacobian_ratio,
                      reorder_hint="; renumber them, or pass orientation='reorder' to mirror their numbering")
        _, first, counts = np.unique(sorted_nodes, axis=0, return_index=True, return_counts=True)
        if np.any(counts > 1):
            dup = np.flatnonzero(np.isin(np.arange(len(elements)), first, invert=True))
            raise ValueError(f"Duplicate {name} elements: {_format_ids(dup)} repeat the node set of an earlier "
                             "element; remove the copies.")
        used = np.zeros(n_nodes, dtype=bool)
        used[elements.ravel()] = True
        if not np.all(used):
            raise ValueError(f"Nodes {_format_ids(np.flatnonzero(~used))} belong to no element; they would be free "
                             "mechanisms of the body. Drop them with SolidMesh.without_unused_nodes(nodes, elements).")
        _check_duplicate_nodes(nodes, elements)
        nodes.flags.writeable = False
        elements.flags.writeable = False
        digest = hashlib.sha256()
        digest.update(np.array(nodes.shape + elements.shape, dtype=np.int64).tobytes())
        digest.update(np.ascontiguousarray(nodes).tobytes())
        digest.update(np.ascontiguousarray(elements).tobytes())
        self.nodes, self.elements, self.cell_type = nodes, elements, cell_type
        self.digest = digest.hexdigest()
        self._hash = hash(self.digest)  # set last: the mesh is frozen from here on

    @staticmethod
    def without_unused_nodes(nodes, elements, **kwargs) -> "tuple[SolidMesh, np.ndarray]":
        """The mesh on the nodes that some element uses, renumbered in their original order.

        **Returns:** `(mesh, kept)`, `kept[i]` the original index of new node `i`.
        """
        nodes, elements = np.asarray(nodes, dtype=np.float64), np.asarray(elements)
        if elements.ndim != 2:
            raise ValueError(f"elements must have shape (n_elements, 8 or 10), got {elements.shape}.")
        kept = np.unique(elements.ravel())
        renumber = np.full(nodes.shape[0], -1, dtype=np.int64)
        renumber[kept] = np.arange(kept.size)
        return SolidMesh(nodes[kept], renumber[elements], **kwargs), kept

    def __setattr__(self, name, value):
        if hasattr(self, "_hash"):
            raise AttributeError(f"SolidMesh is immutable (cannot set {name!r}); build a new mesh instead.")
        object.__setattr__(self, name, value)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other) -> bool:
        return isinstance(other, SolidMesh) and other.digest == self.digest

    def __repr__(self) -> str:
        return (f"SolidMesh({self.cell_type}, n_nodes={self.n_nodes}, n_elements={self.n_elements}, "
                f"digest={self.digest[:12]})")

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        return self.elements.shape[0]

    @property
    def n_dof(self) -> int:
        return 3 * self.n_nodes

    @property
    def nodes_per_element(self) -> int:
        return self.elements.shape[1]

    def element_dofs(self) -> np.ndarray:
        """Global degrees of freedom `(n_elements, 3 k)`: `(u_x, u_y, u_z)` of each node in element order."""
        e = self.elements
        return np.stack([3 * e, 3 * e + 1, 3 * e + 2], axis=-1).reshape(e.shape[0], -1)

    def element_coordinates(self) -> np.ndarray:
        """Node coordinates of each element, `(n_elements, k, 3)`."""
        return self.nodes[self.elements]

    def element_volumes(self) -> np.ndarray:
        """Element volumes `(n_elements,)`: `sum_g det J w_g` over the element's mass rule (exact for trilinear
        hexahedra and straight tetrahedra)."""
        rule, shape_functions = _VOLUME_RULES[self.cell_type]
        xyz = self.element_coordinates()
        return sum(w * jacobian_determinants(shape_functions(*p)[1], xyz) for p, w in rule())

    def check_element(self, element: AbstractSolidElement) -> None:
        """A `ValueError` unless `element` is made for this mesh's cell type."""
        if not isinstance(element, AbstractSolidElement):
            raise TypeError(f"element must be a solid element such as H8(), H11() or Tet10(), got {element!r}.")
        if element.cell_type != self.cell_type:
            raise ValueError(f"{type(element).__name__} elements need a mesh of {element.cell_type} cells; this mesh "
                             f"has {self.cell_type} cells.")


def _check_duplicate_nodes(nodes, elements):
    from scipy.spatial import cKDTree

    xyz = nodes[elements[:, :2]]
    shortest = np.linalg.norm(xyz[:, 1] - xyz[:, 0], axis=-1).min()
    pairs = cKDTree(nodes).query_pairs(DUPLICATE_NODE_TOLERANCE * shortest, output_type="ndarray")
    if pairs.size:
        raise ValueError(
            f"Duplicate nodes: {len(pairs)} pairs of nodes share a position (e.g. nodes {int(pairs[0, 0])} and "
            f"{int(pairs[0, 1])}); the mesh is cut there. Merge coincident nodes (in gmsh: Geometry.Tolerance / "
            "'Coherence') and renumber the elements."
        )


class SolidGrid(SolidMesh):
    """The `nx x ny x nz` hexahedral grid of the box `[0, L] x [-W/2, W/2] x [-H/2, H/2]`, some cells masked out.

    Grid node `(i, j, k)` sits at `(i L / nx, -W/2 + j W / ny, -H/2 + k H / nz)`; grid cell
    `(i, j, k)` has index `c = (k ny + j) nx + i` (the planar `StructuredGrid` numbering, layer
    by layer). Only the cells with `mask[i, j, k]` true are elements, in increasing cell index;
    `cells[e]` is the cell index of element `e`, and only the nodes of some element are nodes of
    the mesh, renumbered in increasing grid index (`grid_nodes[n]` the grid index
    `(i (ny + 1) + j)(nz + 1) + k` of node `n`). Build one with [`box_grid`][].
    """

    __slots__ = ("shape", "size", "cells", "grid_nodes")

    def __init__(self, nx: int, ny: int, nz: int, length: float, width: float, height: float, mask=None):
        for name, n in (("nx", nx), ("ny", ny), ("nz", nz)):
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ValueError(f"{name} must be a positive Python int, got {n!r}.")
        if not (length > 0 and width > 0 and height > 0):
            raise ValueError(f"length, width and height must be positive, got {length}, {width}, {height}.")
        full = np.ones((nx, ny, nz), dtype=bool) if mask is None else np.asarray(mask)
        if full.shape != (nx, ny, nz) or full.dtype != bool:
            raise ValueError(f"mask must be a boolean array of shape (nx, ny, nz) = {(nx, ny, nz)}, got "
                             f"{full.dtype} {full.shape}.")
        if not full.any():
            raise ValueError("mask keeps no cell; keep at least one.")
        i, j, k = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
        grid = np.stack([i * (length / nx), -0.5 * width + j * (width / ny), -0.5 * height + k * (height / nz)],
                        axis=-1).reshape(-1, 3)
        k, j, i = (a.ravel() for a in np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij"))
        cells = np.flatnonzero(full[i, j, k])
        i, j, k = i[cells], j[cells], k[cells]

        def node(a, b, c):
            return (a * (ny + 1) + b) * (nz + 1) + c

        elements = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                             node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1),
                             node(i, j + 1, k + 1)], axis=-1)
        kept = np.unique(elements.ravel())
        renumber = np.full(grid.shape[0], -1, dtype=np.int64)
        renumber[kept] = np.arange(kept.size)
        self.shape = (nx, ny, nz)
        self.size = (float(length), float(width), float(height))
        self.cells = cells
        self.grid_nodes = kept
        super().__init__(grid[kept], renumber[elements])

    def __repr__(self) -> str:
        return (f"SolidGrid(shape={self.shape}, size={self.size}, n_elements={self.n_elements}, "
                f"digest={self.digest[:12]})")


def box_grid(nx: int, ny: int, nz: int, length: float, width: float, height: float, mask=None) -> SolidGrid:
    """The hexahedral `SolidGrid` of the box `[0, L] x [-W/2, W/2] x [-H/2, H/2]`.

    **Arguments:** cell counts `nx, ny, nz` (Python ints); box size `length, width, height`;
    `mask`: optional boolean `(nx, ny, nz)`, the cells that are elements (default all).

    **Returns:** the mesh; with no mask it has `(nx + 1)(ny + 1)(nz + 1)` nodes and `nx ny nz` elements.
    """
    return SolidGrid(nx, ny, nz, length, width, height, mask)


# The six tetrahedra of a hexahedron around its diagonal 0-6 (Kuhn's split, conforming across faces
# when every hexahedron of a grid is split the same way), and the edges of the tetra10 mid-side nodes.
_KUHN = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])
_TET_EDGES = np.array([[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]])


def hex_to_tet10(mesh: SolidMesh) -> SolidMesh:
    """The hexahedral `mesh` split into six straight-edged 10-node tetrahedra per hexahedron.

    Each hexahedron is cut along its diagonal 0–6 (Kuhn), which gives a conforming mesh on
    structured grids ([`box_grid`][]); mid-side nodes are added at the edge midpoints. Element
    `6 e + s` is tetrahedron `s` of hexahedron `e`, so element fields repeat six times. Inverted
    tetrahedra of the split are renumbered (`orientation="reorder"`).

    **Returns:** a [`SolidMesh`][] of `tetra10` cells: the hexahedral nodes first, then the mid-side nodes.
    """
    if not isinstance(mesh, SolidMesh) or mesh.cell_type != "hexahedron":
        raise ValueError(f"hex_to_tet10 needs a hexahedral SolidMesh, got {mesh!r}.")
    tets = mesh.elements[:, _KUHN].reshape(-1, 4)
    pairs = np.sort(tets[:, _TET_EDGES], axis=-1).reshape(-1, 2)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    nodes = np.concatenate([mesh.nodes, 0.5 * (mesh.nodes[unique[:, 0]] + mesh.nodes[unique[:, 1]])])
    mid = mesh.n_nodes + inverse.reshape(-1, 6)
    return SolidMesh(nodes, np.concatenate([tets, mid], axis=1), orientation="reorder")


_SOLID_CELLS = {"hexahedron": 8, "tetra10": 10}
_LOWER_DIMENSIONAL = ("vertex", "line", "line3", "triangle", "triangle6", "quad", "quad8", "quad9")


def solid_from_meshio(mesh, orientation: str = "refuse", min_jacobian_ratio: float | None = None) -> SolidMesh:
    """A [`SolidMesh`][] from a `meshio.Mesh`: its `hexahedron` or `tetra10` cells.

    Lower-dimensional cells (vertices, lines, triangles and quadrilaterals: the boundary entities
    gmsh writes) are ignored and nodes used only by them are dropped. A mesh must hold one solid
    cell type; linear tetrahedra (`tetra`, which lock in bending), wedges, pyramids and quadratic
    hexahedra are refused with a clear error (gmsh: `Mesh.ElementOrder = 2` for `tetra10`).
    `min_jacobian_ratio`: passed to the [`SolidMesh`][] (default its own, 0.05).
    """
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"A solid mesh needs points with 3 coordinates, got shape {points.shape}.")
    types = sorted({block.type for block in mesh.cells})
    bad = [t for t in types if t not in _SOLID_CELLS and t not in _LOWER_DIMENSIONAL]
    if bad:
        raise ValueError(f"Unsupported cell types {bad}: solid meshes must hold 8-node hexahedra ('hexahedron') or "
                         "10-node tetrahedra ('tetra10'). Linear tetrahedra lock in bending: mesh with second-order "
                         "elements (gmsh: Mesh.ElementOrder = 2).")
    solid = [t for t in types if t in _SOLID_CELLS]
    if len(solid) != 1:
        raise ValueError(f"A solid mesh must hold exactly one of the cell types 'hexahedron', 'tetra10'; this one "
                         f"holds {solid or 'none'} (all types: {types}).")
    elements = np.concatenate([block.data for block in mesh.cells if block.type == solid[0]], axis=0)
    quality = {} if min_jacobian_ratio is None else {"min_jacobian_ratio": min_jacobian_ratio}
    return SolidMesh.without_unused_nodes(points, elements, orientation=orientation, **quality)[0]


def solid_cell_data(mesh) -> dict[str, np.ndarray]:
    """The cell data of a `meshio.Mesh` on its solid cells, in the element order of `solid_from_meshio`.

    E.g. `solid_cell_data(m)["gmsh:physical"]`: the physical volume of each element (passive regions,
    materials), to be compared with the tags of the mesh's `field_data`.
    """
    solid = [b.type for b in mesh.cells if b.type in _SOLID_CELLS]
    out = {}
    for name, blocks in mesh.cell_data.items():
        out[name] = np.concatenate([np.asarray(d) for d, b in zip(blocks, mesh.cells) if b.type in solid])
    return out


def read_solid_mesh(path, orientation: str = "refuse", min_jacobian_ratio: float | None = None) -> SolidMesh:
    """Read a hexahedral or quadratic tetrahedral mesh from any file `meshio` reads (`.msh`, `.vtu`, `.inp`, ...).

    See `solid_from_meshio` for what is supported; `min_jacobian_ratio` is passed to the [`SolidMesh`][] (default
    its own, 0.05).
    """
    mesh = read_meshio(path, "read_solid_mesh", "give a mesh file meshio reads (.msh, .vtu, .inp, ...) with its "
                       "usual extension.")
    return solid_from_meshio(mesh, orientation, min_jacobian_ratio)
