"""Planar quadrilateral meshes: nodes and connectivity, checked, hashable by content.

A mesh is static configuration (it decides array shapes and the sparsity of every matrix), so
[`QuadMesh`][] is an immutable host object: NumPy arrays, a SHA-256 digest of its content
computed once, and `__hash__`/`__eq__` by that digest, so that `jax.jit` caches a compiled
program per mesh and never compares arrays. It carries no JAX arrays: the arrays a compiled
program needs (coordinates, element degrees of freedom, element matrices) live as pytree
leaves of [`FEModel`][], where `jit` sees them as inputs and not as constants.

Node `n` has the degrees of freedom `2 n` (`u_x`) and `2 n + 1` (`u_y`). Element `e` has the
nodes `elements[e]`, counter-clockwise.
"""

import hashlib

import numpy as np

from .named_groups import read_meshio


# Gauss points of the 2x2 rule and the corners of the reference square, counter-clockwise.
GAUSS_2 = np.array([-1.0, 1.0]) / np.sqrt(3.0)
CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])

# Smallest admissible ratio min det J / max det J over an element's corners (a ratio of 20:1,
# the limit common FE codes warn at); below it the element is refused as badly distorted.
MIN_JACOBIAN_RATIO = 0.05
# Nodes closer than this fraction of the shortest element edge count as duplicates.
DUPLICATE_NODE_TOLERANCE = 1e-9


def _corner_jacobians(xy: np.ndarray) -> np.ndarray:
    """`det J` of the bilinear map at the four corners of each element, `(m, 4)`.

    For a bilinear quadrilateral `det J = a0 + a1 xi + a2 eta` is linear in the natural
    coordinates, so it is positive everywhere in the element iff it is positive at the corners;
    at corner `a` it is a quarter of the cross product of the two edges that meet there.
    """
    forward = np.roll(xy, -1, axis=1) - xy
    backward = np.roll(xy, 1, axis=1) - xy
    return 0.25 * (forward[..., 0] * backward[..., 1] - forward[..., 1] * backward[..., 0])


def _format_ids(ids, limit: int = 10) -> str:
    ids = [int(i) for i in ids]
    head = ", ".join(str(i) for i in ids[:limit])
    return head + (f", ... ({len(ids)} in all)" if len(ids) > limit else "")


class QuadMesh:
    """A planar mesh of 4-node quadrilaterals, validated at construction and immutable.

    **Arguments:**
    - `nodes`: `(n_nodes, 2)` node coordinates (body frame).
    - `elements`: `(n_elements, 4)` node indices of each element.
    - `orientation`: what to do with clockwise elements (all four corner Jacobians negative):
      `"reorder"` (default) reverses their node order, which describes the same quadrilateral
      counter-clockwise; `"refuse"` raises.
    - `min_jacobian_ratio`: elements with `min det J / max det J` over the corners below this
      (default 0.05) are refused as badly distorted.

    **Raises** `ValueError` with the offending indices for: wrong shapes or non-finite
    coordinates, node indices out of range, repeated nodes within an element, degenerate,
    non-convex or self-intersecting (bow-tie) elements (a corner Jacobian of the wrong sign or
    zero), badly distorted elements, duplicate elements (the same node set twice), unused nodes
    (they would be rigid-body mechanisms; drop them with [`QuadMesh.without_unused_nodes`][]),
    inverted elements folded over a neighbour (two elements on the same side of a shared edge:
    the mesh overlaps itself), and duplicate nodes (two nodes at one position: the mesh would be
    cut there).

    The digest covers the node coordinates and the connectivity after reordering; two meshes
    are equal iff their digests are.
    """

    __slots__ = ("nodes", "elements", "digest", "_hash")

    def __init__(self, nodes, elements, *, orientation: str = "reorder",
                 min_jacobian_ratio: float = MIN_JACOBIAN_RATIO):
        if orientation not in ("reorder", "refuse"):
            raise ValueError(f"orientation must be 'reorder' or 'refuse', got {orientation!r}.")
        nodes = np.array(nodes, dtype=np.float64)
        elements_in = np.asarray(elements)
        if nodes.ndim != 2 or nodes.shape[1] != 2 or nodes.shape[0] < 4:
            raise ValueError(f"nodes must have shape (n_nodes, 2) with n_nodes >= 4, got {nodes.shape}.")
        if not np.all(np.isfinite(nodes)):
            bad = np.flatnonzero(~np.all(np.isfinite(nodes), axis=1))
            raise ValueError(f"Node coordinates must be finite; nodes {_format_ids(bad)} are not.")
        if elements_in.ndim != 2 or elements_in.shape[1] != 4 or elements_in.shape[0] < 1:
            raise ValueError(
                f"elements must have shape (n_elements, 4) (4-node quadrilaterals), got {elements_in.shape}."
            )
        if not np.issubdtype(elements_in.dtype, np.integer):
            if not np.all(elements_in == np.round(elements_in)):
                raise ValueError("elements must hold integer node indices.")
        elements = elements_in.astype(np.int64)
        n_nodes = nodes.shape[0]
        out = np.flatnonzero(np.any((elements < 0) | (elements >= n_nodes), axis=1))
        if out.size:
            raise ValueError(
                f"Elements {_format_ids(out)} refer to node indices outside [0, {n_nodes}); "
                "connectivity must index the rows of nodes (0-based)."
            )
        sorted_nodes = np.sort(elements, axis=1)
        repeated = np.flatnonzero(np.any(np.diff(sorted_nodes, axis=1) == 0, axis=1))
        if repeated.size:
            raise ValueError(
                f"Elements {_format_ids(repeated)} repeat a node (collapsed quadrilaterals, e.g. triangles "
                "written as quads); mesh with true quadrilaterals."
            )
        elements = self._orient(nodes, elements, orientation, min_jacobian_ratio)
        _, first, counts = np.unique(sorted_nodes, axis=0, return_index=True, return_counts=True)
        if np.any(counts > 1):
            dup = np.flatnonzero(np.isin(np.arange(len(elements)), first, invert=True))
            raise ValueError(
                f"Duplicate elements: {_format_ids(dup)} repeat the node set of an earlier element; "
                "remove the copies."
            )
        self._check_folds(elements)
        used = np.zeros(n_nodes, dtype=bool)
        used[elements.ravel()] = True
        if not np.all(used):
            raise ValueError(
                f"Nodes {_format_ids(np.flatnonzero(~used))} belong to no element; they would be free "
                "mechanisms of the body. Drop them with QuadMesh.without_unused_nodes(nodes, elements)."
            )
        self._check_duplicate_nodes(nodes, elements)
        nodes.flags.writeable = False
        elements.flags.writeable = False
        digest = hashlib.sha256()
        digest.update(np.array(nodes.shape + elements.shape, dtype=np.int64).tobytes())
        digest.update(np.ascontiguousarray(nodes).tobytes())
        digest.update(np.ascontiguousarray(elements).tobytes())
        self.nodes = nodes
        self.elements = elements
        self.digest = digest.hexdigest()
        self._hash = hash(self.digest)  # set last: the mesh is frozen from here on

    @staticmethod
    def _orient(nodes, elements, orientation, min_ratio):
        jac = _corner_jacobians(nodes[elements])
        clockwise = np.all(jac < 0.0, axis=1)
        if np.any(clockwise):
            if orientation == "refuse":
                raise ValueError(
                    f"Elements {_format_ids(np.flatnonzero(clockwise))} are numbered clockwise; number them "
                    "counter-clockwise, or pass orientation='reorder' to reverse them."
                )
            elements = elements.copy()
            elements[clockwise] = elements[clockwise][:, ::-1]
            jac[clockwise] = -jac[clockwise][:, ::-1]
        invalid = np.flatnonzero(np.any(jac <= 0.0, axis=1))
        if invalid.size:
            raise ValueError(
                f"Elements {_format_ids(invalid)} are degenerate, non-convex or self-intersecting (the "
                "Jacobian of the bilinear map changes sign or vanishes at a corner); remesh them."
            )
        ratio = jac.min(axis=1) / jac.max(axis=1)
        distorted = np.flatnonzero(ratio < min_ratio)
        if distorted.size:
            raise ValueError(
                f"Elements {_format_ids(distorted)} are badly distorted (corner Jacobian ratio "
                f"{ratio[distorted].min():.3g} < {min_ratio}); remesh them (smaller or smoothed elements there), or "
                "pass a lower min_jacobian_ratio (an argument of QuadMesh, from_meshio, read_mesh and "
                "read_planar_groups) if you accept the loss of accuracy."
            )
        return elements

    @staticmethod
    def _check_folds(elements):
        """Counter-clockwise elements that share an edge run along it in opposite directions; two
        elements running along an edge in the same direction lie on the same side of it: one of
        them is inverted (folded over its neighbour), and the mesh overlaps itself."""
        edges = np.stack([elements, np.roll(elements, -1, axis=1)], axis=-1).reshape(-1, 2)
        _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
        repeated = np.flatnonzero(counts[inverse.ravel()] > 1)
        if repeated.size:
            owners = np.unique(repeated // 4)
            a, b = edges[repeated[0]]
            raise ValueError(
                f"Elements {_format_ids(owners)} overlap: they lie on the same side of a shared edge (e.g. nodes "
                f"{int(a)}-{int(b)}), so an element is inverted (folded over its neighbour). Remesh there, or fix "
                "the node order of the inverted element together with its position."
            )

    @staticmethod
    def _check_duplicate_nodes(nodes, elements):
        from scipy.spatial import cKDTree

        xy = nodes[elements]
        edges = np.linalg.norm(np.roll(xy, -1, axis=1) - xy, axis=-1)
        tolerance = DUPLICATE_NODE_TOLERANCE * edges.min()
        pairs = cKDTree(nodes).query_pairs(tolerance, output_type="ndarray")
        if pairs.size:
            raise ValueError(
                f"Duplicate nodes: {len(pairs)} pairs of nodes share a position (e.g. nodes "
                f"{int(pairs[0, 0])} and {int(pairs[0, 1])}); the mesh is cut there. Merge coincident "
                "nodes (in gmsh: Geometry.Tolerance / 'Coherence') and renumber the elements."
            )

    @staticmethod
    def without_unused_nodes(nodes, elements, **kwargs) -> "tuple[QuadMesh, np.ndarray]":
        """The mesh on the nodes that some element uses, renumbered in their original order (`kwargs`:
        `orientation`, `min_jacobian_ratio` of the [`QuadMesh`][]).

        **Returns:** `(mesh, kept)`, `kept[i]` the original index of new node `i`.
        """
        nodes, elements = np.asarray(nodes, dtype=np.float64), np.asarray(elements)
        if elements.ndim != 2 or elements.shape[1] != 4:
            raise ValueError(f"elements must have shape (n_elements, 4), got {elements.shape}.")
        kept = np.unique(elements.ravel())
        renumber = np.full(nodes.shape[0], -1, dtype=np.int64)
        renumber[kept] = np.arange(kept.size)
        return QuadMesh(nodes[kept], renumber[elements], **kwargs), kept

    def __setattr__(self, name, value):
        if hasattr(self, "_hash"):
            raise AttributeError(f"QuadMesh is immutable (cannot set {name!r}); build a new mesh instead.")
        object.__setattr__(self, name, value)

    # --- identity ---------------------------------------------------------------------------
    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other) -> bool:
        return isinstance(other, QuadMesh) and other.digest == self.digest

    def __repr__(self) -> str:
        return f"QuadMesh(n_nodes={self.n_nodes}, n_elements={self.n_elements}, digest={self.digest[:12]})"

    # --- layout -----------------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        return self.elements.shape[0]

    @property
    def n_dof(self) -> int:
        return 2 * self.n_nodes

    def element_dofs(self) -> np.ndarray:
        """Global degrees of freedom `(n_elements, 8)`: `(u_x, u_y)` of each node, counter-clockwise."""
        return np.stack([2 * self.elements, 2 * self.elements + 1], axis=-1).reshape(-1, 8)

    def element_coordinates(self) -> np.ndarray:
        """Corner coordinates `(n_elements, 4, 2)`."""
        return self.nodes[self.elements]

    def element_areas(self) -> np.ndarray:
        """Element areas `(n_elements,)` (shoelace formula)."""
        xy = self.element_coordinates()
        nxt = np.roll(xy, -1, axis=1)
        return 0.5 * np.sum(xy[..., 0] * nxt[..., 1] - nxt[..., 0] * xy[..., 1], axis=1)

    def element_centroids(self) -> np.ndarray:
        """Area centroids `(n_elements, 2)` of the elements (split along the diagonal 0–2)."""
        xy = self.element_coordinates()

        def triangle(a, b, c):
            area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
            return area, (a + b + c) / 3.0

        a1, c1 = triangle(xy[:, 0], xy[:, 1], xy[:, 2])
        a2, c2 = triangle(xy[:, 0], xy[:, 2], xy[:, 3])
        return (a1[:, None] * c1 + a2[:, None] * c2) / (a1 + a2)[:, None]

    def jacobian_ratios(self) -> np.ndarray:
        """`min det J / max det J` over the corners of each element, `(n_elements,)`, 1 for parallelograms."""
        jac = _corner_jacobians(self.element_coordinates())
        return jac.min(axis=1) / jac.max(axis=1)

    def nodes_near(self, point, radius: float) -> tuple[int, ...]:
        """Nodes within `radius` of `point` (e.g. the rim of a hole), sorted."""
        d = np.linalg.norm(self.nodes - np.asarray(point, dtype=float), axis=1)
        return tuple(int(i) for i in np.flatnonzero(d <= radius))

    def check_nodes(self, nodes, what: str) -> tuple[int, ...]:
        """Validate node indices (interfaces, markers): integers in `[0, n_nodes)`, no repeats."""
        try:
            arr = np.asarray(nodes).ravel()
        except Exception as err:  # pragma: no cover - numpy accepts nearly everything
            raise ValueError(f"{what}: expected node indices, got {nodes!r}.") from err
        if arr.size == 0:
            raise ValueError(f"{what}: no nodes given.")
        if not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"{what}: node indices must be integers, got {arr.dtype}.")
        bad = arr[(arr < 0) | (arr >= self.n_nodes)]
        if bad.size:
            raise ValueError(f"{what}: nodes {_format_ids(bad)} are not in the mesh (it has {self.n_nodes} nodes).")
        if np.unique(arr).size != arr.size:
            raise ValueError(f"{what}: node indices repeat.")
        return tuple(int(i) for i in arr)


class StructuredGrid(QuadMesh):
    """The `nx x ny` grid over `[0, L] x [-h/2, h/2]`: a [`QuadMesh`][] that also knows its layout.

    Node `(i, j)` (column `i = 0..nx`, row `j = 0..ny`) sits at `(i L / nx, -h/2 + j h / ny)` with
    index `i (ny + 1) + j`; element `(i, j)` has the nodes `(i, j), (i+1, j), (i+1, j+1), (i, j+1)`
    and index `j nx + i` (REFERENCE_CASE §1). The attributes `nx`, `ny`, `length`, `height` (and
    `dx`, `dy`) follow from the content, so equality and hashing stay those of the mesh content.
    Build one with [`structured_grid`][].
    """

    __slots__ = ("nx", "ny", "length", "height")

    def __init__(self, nx: int, ny: int, length: float, height: float):
        if not (isinstance(nx, int) and isinstance(ny, int)) or nx < 1 or ny < 1:
            raise ValueError(f"nx and ny must be positive Python ints, got {nx!r}, {ny!r}.")
        if not (length > 0 and height > 0):
            raise ValueError(f"length and height must be positive, got {length}, {height}.")
        self.nx, self.ny, self.length, self.height = nx, ny, float(length), float(height)
        dx, dy = self.dx, self.dy
        i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
        nodes = np.stack([i * dx, -0.5 * height + j * dy], axis=-1).reshape(-1, 2)
        j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        i, j = i.ravel(), j.ravel()
        elements = np.stack([self.node(i, j), self.node(i + 1, j), self.node(i + 1, j + 1), self.node(i, j + 1)],
                            axis=-1)
        super().__init__(nodes, elements, orientation="refuse")

    @property
    def dx(self) -> float:
        """Element size along x, `L / nx`."""
        return self.length / self.nx

    @property
    def dy(self) -> float:
        """Element size along y, `h / ny`."""
        return self.height / self.ny

    def node(self, i, j):
        """Index of node `(i, j)` (column, row), `i (ny + 1) + j`."""
        return i * (self.ny + 1) + j

    def element(self, i, j):
        """Index of element `(i, j)` (column, row), `j nx + i`."""
        return j * self.nx + i

    def __repr__(self) -> str:
        return (f"StructuredGrid(nx={self.nx}, ny={self.ny}, length={self.length}, height={self.height}, "
                f"digest={self.digest[:12]})")


def structured_grid(nx: int, ny: int, length: float, height: float) -> StructuredGrid:
    """The `nx x ny` `StructuredGrid` over `[0, L] x [-h/2, h/2]` (the numbering of the reference rod).

    **Returns:** a mesh with `(nx + 1)(ny + 1)` nodes and `nx ny` elements.
    """
    return StructuredGrid(nx, ny, length, height)


# meshio cell types that are planar elements but not 4-node quadrilaterals.
_UNSUPPORTED_2D = ("triangle", "triangle6", "triangle7", "quad8", "quad9", "polygon")


def from_meshio(mesh, min_jacobian_ratio: float | None = None) -> QuadMesh:
    """A [`QuadMesh`][] from a `meshio.Mesh`: its `quad` cells, nodes not used by them dropped.

    Lines and vertices (boundary and point entities, as gmsh writes them) are ignored; nodes used
    only by them are dropped and the rest renumbered in their original order. Clockwise quads are
    reordered counter-clockwise. Unsupported: triangles, quadratic quads (`quad8`, `quad9`),
    polygons and volume cells (a clear error: recombine to linear quadrilaterals, e.g. gmsh
    `Mesh.RecombineAll = 1` and `Mesh.ElementOrder = 1`), and points off the plane `z = 0`.

    Cell data of the quads (e.g. `gmsh:physical`) in the same element order: `quad_cell_data`; the
    named physical groups: [`planar_groups_from_meshio`][]. `min_jacobian_ratio`: passed to the
    [`QuadMesh`][] (default its own, 0.05).
    """
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise ValueError(f"mesh points must have 2 or 3 coordinates, got shape {points.shape}.")
    if points.shape[1] == 3:
        scale = max(np.abs(points[:, :2]).max(), 1e-300)
        if np.abs(points[:, 2]).max() > 1e-12 * scale:
            raise ValueError("The mesh is not planar: its points must lie in the plane z = 0.")
        points = points[:, :2]
    types = [block.type for block in mesh.cells]
    bad = sorted({t for t in types if t in _UNSUPPORTED_2D or t not in ("quad", "line", "line3", "vertex")})
    if bad:
        raise ValueError(
            f"Unsupported cell types {bad}: only 4-node quadrilaterals ('quad') are supported (lines and "
            "vertices are ignored). Recombine the mesh to linear quadrilaterals (gmsh: Mesh.RecombineAll = 1, "
            "Mesh.ElementOrder = 1; or Mesh.SubdivisionAlgorithm = 1 for an all-quad mesh), or mesh the part with "
            "fj.link_profile."
        )
    quads = [block.data for block in mesh.cells if block.type == "quad"]
    if not quads:
        raise ValueError("The mesh has no 'quad' cells.")
    elements = np.concatenate(quads, axis=0)
    quality = {} if min_jacobian_ratio is None else {"min_jacobian_ratio": min_jacobian_ratio}
    return QuadMesh.without_unused_nodes(points, elements, **quality)[0]


def quad_cell_data(mesh) -> dict[str, np.ndarray]:
    """The cell data of a `meshio.Mesh` on its quads, in the element order of [`from_meshio`][]."""
    out = {}
    for name, blocks in mesh.cell_data.items():
        out[name] = np.concatenate([np.asarray(d) for d, b in zip(blocks, mesh.cells) if b.type == "quad"])
    return out


def read_mesh(path, min_jacobian_ratio: float | None = None) -> QuadMesh:
    """Read a quadrilateral mesh from any file `meshio` reads (`.msh`, `.vtu`, `.inp`, `.med`, ...).

    See [`from_meshio`][] for what is supported; `min_jacobian_ratio` is passed to the [`QuadMesh`][]
    (default its own, 0.05). A gmsh file's named physical groups: [`read_planar_groups`][].
    """
    mesh = read_meshio(path, "read_mesh", "give a mesh file meshio reads (.msh, .vtu, .inp, .med, ...) with its "
                       "usual extension.")
    return from_meshio(mesh, min_jacobian_ratio)


def write_mesh(path, mesh: QuadMesh, cell_data: dict[str, np.ndarray] | None = None,
               file_format: str | None = None) -> None:
    """Write a [`QuadMesh`][] and per-element data through `meshio`.

    The format follows the file extension unless `file_format` names one (e.g. `"gmsh22"`, which
    keeps `gmsh:physical` tags; meshio's default Gmsh 4.1 writer drops them).
    """
    import meshio

    data = {k: [np.asarray(v)] for k, v in (cell_data or {}).items()}
    meshio.write(path, meshio.Mesh(np.asarray(mesh.nodes), [("quad", np.asarray(mesh.elements))], cell_data=data),
                 file_format=file_format)
