"""Design domains from geometry: the reference rod, a plate with a hole, a link with two pin holes.

The link is meshed with gmsh (imported only inside [`link_with_holes`][], so the package imports
without it); the rod and the plate are structured and need nothing beyond NumPy.
"""

from typing import NamedTuple

import numpy as np

from .domain import DesignDomain
from .mesh import QuadMesh, structured_grid


def rod_domain(nx: int, ny: int, length: float = 1.0, height: float = 0.06) -> DesignDomain:
    """The rod of REFERENCE_CASE §1: an `nx x ny` grid whose first and last element columns are solid.

    Design variables in ascending element order, i.e. row-major `x.reshape(ny, nx - 2)[j, i - 1]`,
    the order of the reference case.
    """
    if not (isinstance(nx, int) and nx >= 3):
        raise ValueError(f"nx must be an int >= 3 (two solid end columns and design columns), got {nx!r}.")
    mesh = structured_grid(nx, ny, length, height)
    column = np.arange(mesh.n_elements) % nx
    return DesignDomain.from_masks(mesh, solid=(column == 0) | (column == nx - 1))


def rod_joint_nodes(nx: int, ny: int) -> tuple[int, int]:
    """Joint points `A = (0, 0)` and `B = (L, 0)` of the rod (mid-height nodes of the end edges)."""
    if ny % 2:
        raise ValueError(f"ny must be even so that the joints are nodes at mid-height, got {ny}.")
    return ny // 2, nx * (ny + 1) + ny // 2


class PlateWithHole(NamedTuple):
    """A square plate with a central circular hole: mesh, outer-edge nodes and hole-rim nodes."""

    mesh: QuadMesh
    outer_nodes: tuple[int, ...]
    rim_nodes: tuple[int, ...]


def plate_with_hole(side: float, radius: float, n: int, grading: float = 1.0) -> PlateWithHole:
    """A structured O-grid of the square `[-side/2, side/2]^2` around a central hole of `radius`.

    Four patches (one per side) of `n x n` elements: node `(k, l)` (`k` around, `l` outward) lies
    at `C_k + s_l (S_k - C_k)` between the hole point `C_k` (uniform in angle) and the side point
    `S_k` (uniform along the side), `s_l = (l / n)^grading`. Halving `n` nests the meshes, so
    frequencies converge regularly (order 2 for Q4 and QM6) and extrapolate (Richardson).

    **Returns:** a `PlateWithHole` with `4 n^2` elements.
    """
    if not 0 < radius < side / 2:
        raise ValueError(f"radius must lie in (0, side/2), got {radius} for side {side}.")
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n must be a positive int, got {n!r}.")
    a = side / 2
    n_ring = 4 * n
    t = -1.0 + 2.0 * (np.arange(n_ring) % n) / n  # position along the current side, [-1, 1)
    side_index = np.arange(n_ring) // n  # 0: right (x = a), 1: top, 2: left, 3: bottom
    angle = side_index * np.pi / 2 + np.pi / 4 * t
    circle = radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    local = np.stack([np.full(n_ring, a), a * t], axis=-1)  # the right side, rotated into place below
    rot = side_index * np.pi / 2
    square = np.stack([np.cos(rot) * local[:, 0] - np.sin(rot) * local[:, 1],
                       np.sin(rot) * local[:, 0] + np.cos(rot) * local[:, 1]], axis=-1)
    s = (np.arange(n + 1) / n) ** grading
    nodes = (circle[None] + s[:, None, None] * (square - circle)[None]).reshape(-1, 2)

    def node(k, l):
        return l * n_ring + k % n_ring

    k, l = np.meshgrid(np.arange(n_ring), np.arange(n), indexing="ij")
    k, l = k.ravel(), l.ravel()
    elements = np.stack([node(k, l), node(k, l + 1), node(k + 1, l + 1), node(k + 1, l)], axis=-1)
    mesh = QuadMesh(nodes, elements, orientation="refuse")
    return PlateWithHole(mesh, tuple(int(i) for i in node(np.arange(n_ring), n)),
                         tuple(int(i) for i in node(np.arange(n_ring), 0)))


class LinkMesh(NamedTuple):
    """A meshed link with two pin holes.

    - `mesh`: the [`QuadMesh`][]; `domain`: its [`DesignDomain`][] with the rims passive solid.
    - `rims`: for each hole, the nodes on its boundary circle (interfaces, markers).
    - `centres`: `(2, 2)` hole centres; `rim_elements`: boolean mask of the rim elements.
    """

    mesh: QuadMesh
    domain: DesignDomain
    rims: tuple[tuple[int, ...], tuple[int, ...]]
    centres: np.ndarray
    rim_elements: np.ndarray


def link_with_holes(length: float = 0.2, width: float = 0.05, hole_radius: float = 0.008,
                    rim_width: float = 0.005, mesh_size: float = 0.004) -> LinkMesh:
    """A link with rounded ends and two pin holes, meshed in quadrilaterals with gmsh.

    The outline is the rectangle `[0, length] x [-width/2, width/2]` with half-discs of diameter
    `width` at both ends; holes of `hole_radius` at `(0, 0)` and `(length, 0)`, each surrounded
    by an annular rim of `rim_width` (a separate surface, so that its elements are passive solid
    and its boundary is a mesh curve). Frontal-Delaunay for quads with Blossom full-quad
    recombination (every element a quadrilateral), target element size `mesh_size`.

    **Returns:** a `LinkMesh`; the rims' boundary nodes serve as interfaces and markers.
    """
    if not (hole_radius > 0 and rim_width > 0 and hole_radius + rim_width < width / 2):
        raise ValueError(f"Need 0 < hole_radius, 0 < rim_width and hole_radius + rim_width < width / 2, got "
                         f"{hole_radius}, {rim_width}, {width}.")
    if not (0 < mesh_size <= rim_width and length > width):
        raise ValueError(f"Need 0 < mesh_size <= rim_width (at least one element across a rim) and length > width, "
                         f"got mesh_size={mesh_size}, rim_width={rim_width}, length={length}, width={width}.")
    import gmsh

    centres = np.array([[0.0, 0.0], [length, 0.0]])
    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("ffr_jax_link")
        occ = gmsh.model.occ
        outline = occ.fuse([(2, occ.addRectangle(0.0, -width / 2, 0.0, length, width))],
                           [(2, occ.addDisk(x, 0.0, 0.0, width / 2, width / 2)) for x, _ in centres])[0]
        holes = [(2, occ.addDisk(x, 0.0, 0.0, hole_radius, hole_radius)) for x, _ in centres]
        plate = occ.cut(outline, holes)[0]
        rims = []
        for x, _ in centres:
            outer = occ.addDisk(x, 0.0, 0.0, hole_radius + rim_width, hole_radius + rim_width)
            inner = occ.addDisk(x, 0.0, 0.0, hole_radius, hole_radius)
            rims += occ.cut([(2, outer)], [(2, inner)])[0]
        occ.fragment(plate, rims)
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * mesh_size)
        gmsh.option.setNumber("Mesh.Algorithm", 8)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 3)
        gmsh.option.setNumber("Mesh.Smoothing", 10)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(tags.size)
        xy = coords.reshape(-1, 3)[:, :2]
        elements, in_rim = [], []
        for _, surface in gmsh.model.getEntities(2):
            types, _, node_tags = gmsh.model.mesh.getElements(2, surface)
            if any(t != 3 for t in types):
                raise RuntimeError("gmsh left non-quadrilateral elements; refine mesh_size, or mesh the link with "
                                   "fj.link_profile (an all-quadrilateral recipe).")
            quads = index[np.asarray(node_tags[0], dtype=np.int64)].reshape(-1, 4)
            centre = np.asarray(occ.getCenterOfMass(2, surface))[:2]
            is_rim = np.min(np.linalg.norm(centres - centre, axis=1)) < 1e-9 * length
            elements.append(quads)
            in_rim.append(np.full(len(quads), is_rim))
        gmsh.model.remove()
    finally:
        if not initialised:
            gmsh.finalize()
    mesh, _ = QuadMesh.without_unused_nodes(xy, np.concatenate(elements))
    rim_mask = np.concatenate(in_rim)
    rim_nodes = tuple(
        tuple(int(i) for i in np.flatnonzero(np.abs(np.linalg.norm(mesh.nodes - c, axis=1) - hole_radius)
                                             <= 1e-6 * hole_radius))
        for c in centres
    )
    return LinkMesh(mesh, DesignDomain.from_masks(mesh, solid=rim_mask), rim_nodes, centres, rim_mask)
