"""A planar part meshed in quadrilaterals with gmsh: an outline with filleted corners, pin holes with passive rims,
slots with rounded ends or corners, and named physical groups.

The recipe (the settings that mesh every shape of tests/test_link_profile.py's sweep; with gmsh 4.15, full-quad
Blossom recombination, `Mesh.RecombinationAlgorithm` 2 or 3, left triangles on such parts or failed with "1D mesh
cannot be divided by 2" on rounded slots, and gave corner-Jacobian ratios down to 0.03):
1. the geometry from lines and arcs (gmsh's built-in kernel, no Boolean operations): the rim's outer circle is
   the curve shared by the rim and the design region, so the rim is a surface of its own;
2. Frontal-Delaunay triangles (`Mesh.Algorithm` 6) of twice the target size, recombined (Blossom,
   `Mesh.RecombinationAlgorithm` 1) and split into quadrilaterals (`Mesh.SubdivisionAlgorithm` 1): every
   element a quadrilateral, whatever the parity of the boundary;
3. a guarded relocation of the inner nodes (`quad_relocation`) that raises the worst corner-Jacobian ratios.

gmsh is imported only inside [`link_profile`][ffr_jax.link_profile], so the package imports without it.
"""

import dataclasses
import pathlib
from typing import NamedTuple

import numpy as np

from .mesh import _corner_jacobians
from .planar_groups import PlanarGroups, planar_groups_from_meshio
from .quad_relocation import jacobian_ratios, relocate_nodes

_ARC_POINTS = 24  # sample points per quarter turn in the geometry checks (chord error 0.2 % of the radius)


class Hole(NamedTuple):
    """A circular pin hole (a bore) of [`link_profile`][ffr_jax.link_profile].

    - `centre`: `(x, y)`; `radius`: the bore's radius.
    - `rim`: width of the passive solid ring around it (0: no ring, the bore cuts the design region).
    - `name`: the hole's name in the groups (`"bore_<name>"`); default `"A"`, `"B"`, ... in order.
    """

    centre: tuple[float, float]
    radius: float
    rim: float = 0.0
    name: str | None = None


class Slot(NamedTuple):
    """A slot (a lightening hole) of [`link_profile`][ffr_jax.link_profile]: a rectangle with rounded corners.

    - `centre`: `(x, y)`; `length`, `width`: its overall size along and across its axis.
    - `corner_radius`: radius of its corners; `None` (default) is `width / 2`, fully rounded ends.
    - `angle`: direction of its axis (radians, counter-clockwise from x).
    """

    centre: tuple[float, float]
    length: float
    width: float
    corner_radius: float | None = None
    angle: float = 0.0


@dataclasses.dataclass(frozen=True)
class QuadMeshing:
    """Options of [`link_profile`][ffr_jax.link_profile]'s quadrilateral meshing (the defaults are the tested recipe).

    - `algorithm`: gmsh's `Mesh.Algorithm` for the triangles before recombination (6: Frontal-Delaunay).
    - `circle_points`: elements around each bore and rim circle at least, before the split into quadrilaterals,
      which doubles it (the element size at the circles' points; the fillets keep the target size, so that a
      small fillet does not crowd small elements into a corner).
    - `target_ratio`, `passes`: the node relocation raises elements below this corner-Jacobian ratio, in at most
      `passes` sweeps (0: off).
    - `min_jacobian_ratio`: the mesh is refused below this ratio (see [`QuadMesh`][]), with the advice to
      refine.
    """

    algorithm: int = 6
    circle_points: int = 16
    target_ratio: float = 0.5
    passes: int = 4
    min_jacobian_ratio: float = 0.2

    def __post_init__(self):
        if self.algorithm not in (1, 2, 5, 6, 8):
            raise ValueError(f"algorithm must be a gmsh 2-D triangle algorithm (1, 2, 5, 6 or 8), got "
                             f"{self.algorithm!r}.")
        if not (isinstance(self.circle_points, int) and self.circle_points >= 4):
            raise ValueError(f"circle_points must be an int >= 4, got {self.circle_points!r}.")
        if not (0.0 < self.target_ratio <= 1.0 and 0.0 < self.min_jacobian_ratio <= 1.0):
            raise ValueError(f"target_ratio and min_jacobian_ratio must lie in (0, 1], got {self.target_ratio} and "
                             f"{self.min_jacobian_ratio}.")
        if not (isinstance(self.passes, int) and self.passes >= 0):
            raise ValueError(f"passes must be an int >= 0, got {self.passes!r}.")


# --- geometry --------------------------------------------------------------------------------------------------
def _polygon(vertices, what: str) -> tuple[np.ndarray, bool]:
    """The vertices `(n, 2)` checked, and whether they run clockwise."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3 or not np.all(np.isfinite(v)):
        raise ValueError(f"The {what} must be (n, 2) finite vertex coordinates with n >= 3, got shape {v.shape}.")
    edges = np.roll(v, -1, axis=0) - v
    if np.any(np.linalg.norm(edges, axis=1) <= 1e-12 * np.ptp(v, axis=0).max()):
        raise ValueError(f"The {what} repeats a vertex (an edge of zero length); give each corner once.")
    n = len(v)
    for i in range(n):
        for j in range(i + 2, n - (i == 0)):
            if _segments_cross(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]):
                raise ValueError(f"The {what} crosses itself (edges {i} and {j}); give its corners in order around it.")
    area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
    return v, bool(area < 0)


def _segments_cross(a, b, c, d) -> bool:
    def side(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    return bool(side(a, b, c) * side(a, b, d) <= 0 and side(c, d, a) * side(c, d, b) <= 0)


def _rounded(vertices: np.ndarray, radii, what: str) -> list:
    """The closed outline of a counter-clockwise polygon with corner arcs: `("line", p, q)` and
    `("arc", p, centre, q)` pieces in order (a straight edge used up by its two arcs is left out)."""
    n = len(vertices)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (n,))
    if np.any(radii < 0) or not np.all(np.isfinite(radii)):
        raise ValueError(f"The fillet radii of the {what} must be finite and >= 0, got {radii}.")
    corners, tangent = [], np.zeros(n)
    for i in range(n):
        p = vertices[i]
        u = vertices[i - 1] - p
        w = vertices[(i + 1) % n] - p
        u, w = u / np.linalg.norm(u), w / np.linalg.norm(w)
        half = 0.5 * np.arccos(np.clip(u @ w, -1.0, 1.0))
        if radii[i] == 0.0:
            corners.append((p, None, p))
            continue
        tangent[i] = radii[i] / np.tan(half)
        bisector = (u + w) / np.linalg.norm(u + w)
        corners.append((p + tangent[i] * u, p + bisector * radii[i] / np.sin(half), p + tangent[i] * w))
    lengths = np.linalg.norm(np.roll(vertices, -1, axis=0) - vertices, axis=1)
    used = tangent + np.roll(tangent, -1)
    over = np.flatnonzero(used > lengths * (1 + 1e-9))
    if over.size:
        i = int(over[0])
        raise ValueError(f"The fillets at corners {i} and {(i + 1) % n} of the {what} need {used[i]:.6g} of the edge "
                         f"between them, which is {lengths[i]:.6g} long; give smaller fillet radii.")
    pieces = []
    for i in range(n):
        start, centre, end = corners[i]
        if centre is not None:
            pieces.append(("arc", start, centre, end))
        if used[i] < lengths[i] * (1 - 1e-9):
            pieces.append(("line", end, corners[(i + 1) % n][0]))
    return pieces


def _circle(centre, radius: float) -> list:
    c = np.asarray(centre, dtype=np.float64)
    points = [c + radius * np.array([np.cos(a), np.sin(a)]) for a in np.arange(4) * np.pi / 2]
    return [("arc", points[k], c, points[(k + 1) % 4]) for k in range(4)]


def _slot_pieces(slot: Slot) -> list:
    if not (slot.length > 0 and slot.width > 0 and slot.length >= slot.width):
        raise ValueError(f"A slot needs 0 < width <= length, got length {slot.length} and width {slot.width}.")
    radius = 0.5 * slot.width if slot.corner_radius is None else float(slot.corner_radius)
    if not 0.0 <= radius <= 0.5 * slot.width * (1 + 1e-12):
        raise ValueError(f"A slot's corner_radius must lie in [0, width / 2] = [0, {0.5 * slot.width}], got {radius}.")
    radius = min(radius, 0.5 * slot.width)
    c, s = np.cos(slot.angle), np.sin(slot.angle)
    box = 0.5 * np.array([[-slot.length, -slot.width], [slot.length, -slot.width], [slot.length, slot.width],
                          [-slot.length, slot.width]])
    corners = box @ np.array([[c, s], [-s, c]]) + np.asarray(slot.centre, dtype=np.float64)
    return _rounded(corners, radius, "slot")


def _sample(pieces: list) -> np.ndarray:
    """Points along a closed outline of pieces, `(m, 2)` (arcs at `_ARC_POINTS` per quarter turn)."""
    points = []
    for piece in pieces:
        if piece[0] == "line":
            points.append(piece[1])
            continue
        _, start, centre, end = piece
        a0 = np.arctan2(*(start - centre)[::-1])
        sweep = (np.arctan2(*(end - centre)[::-1]) - a0 + np.pi) % (2 * np.pi) - np.pi
        radius = np.linalg.norm(start - centre)
        count = max(2, int(np.ceil(abs(sweep) / (np.pi / 2) * _ARC_POINTS)))
        for a in a0 + sweep * np.arange(count) / count:
            points.append(centre + radius * np.array([np.cos(a), np.sin(a)]))
    return np.array(points)


def _inside(points: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon of `points` `(m, 2)` in the closed polyline `loop` `(k, 2)`."""
    a, b = loop, np.roll(loop, -1, axis=0)
    x, y = points[:, None, 0], points[:, None, 1]
    crosses = ((a[:, 1] > y) != (b[:, 1] > y)) & (
        x < a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1]))
    return np.count_nonzero(crosses, axis=1) % 2 == 1


def _distance(points: np.ndarray, loop: np.ndarray) -> float:
    """Smallest distance from `points` `(m, 2)` to the segments of the closed polyline `loop`."""
    a, d = loop, np.roll(loop, -1, axis=0) - loop
    t = np.clip(np.einsum("mkj,kj->mk", points[:, None] - a, d) / np.einsum("kj,kj->k", d, d), 0.0, 1.0)
    return float(np.linalg.norm(points[:, None] - (a + t[..., None] * d), axis=-1).min())


def _check_layout(outline: list, holes: tuple, slots: list, gap: float) -> None:
    """Every hole's ring and every slot inside the outline, apart from each other, by at least `gap`."""
    boundary = _sample(outline)
    features = [(f"hole {h.name!r} (with its rim)", _sample(_circle(h.centre, h.radius + h.rim))) for h in holes]
    features += [(f"slot {k}", _sample(pieces)) for k, pieces in enumerate(slots)]
    for i, (name, loop) in enumerate(features):
        if not np.all(_inside(loop, boundary)) or _distance(loop, boundary) < gap:
            raise ValueError(f"The {name} reaches within {gap:.3g} (mesh_size) of the outline or beyond it; keep at "
                             "least one element between a feature and the outline: move or shrink the feature, or "
                             "give a smaller mesh_size.")
        for other, loop_2 in features[:i]:
            if np.any(_inside(loop, loop_2)) or np.any(_inside(loop_2, loop)) or _distance(loop, loop_2) < gap:
                raise ValueError(f"The {name} and the {other} overlap or come within {gap:.3g} (mesh_size) of each "
                                 "other; keep at least one element between them: move or shrink one, or give a "
                                 "smaller mesh_size.")


def _holes(holes, mesh_size: float) -> tuple:
    holes = tuple(h if isinstance(h, Hole) else Hole(*h) for h in holes)
    if not holes:
        raise ValueError("link_profile needs at least one Hole (the bores are the part's interfaces).")
    named = []
    for k, h in enumerate(holes):
        name = h.name if h.name is not None else chr(ord("A") + k) if k < 26 else f"H{k}"
        if not (np.shape(h.centre) == (2,) and h.radius > 0 and h.rim >= 0):
            raise ValueError(f"Hole {name!r}: need a centre (x, y), radius > 0 and rim >= 0, got {h}.")
        if 0 < h.rim < mesh_size:
            raise ValueError(f"Hole {name!r}: its rim ({h.rim}) is narrower than mesh_size ({mesh_size}); give "
                             f"mesh_size <= {h.rim} (at least one element across the rim) or a wider rim.")
        named.append(h._replace(centre=tuple(float(c) for c in h.centre), name=name))
    names = [h.name for h in named]
    if len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"Hole names must be distinct non-empty str, got {names}.")
    return tuple(named)


# --- gmsh ------------------------------------------------------------------------------------------------------
def _loop(geo, pieces: list, points: dict) -> tuple[int, list[int]]:
    """A gmsh curve loop of the pieces (points shared through `points`), and its curves."""

    def point(p):
        key = (round(float(p[0]), 12), round(float(p[1]), 12))
        if key not in points:
            points[key] = geo.addPoint(p[0], p[1], 0.0)
        return points[key]

    curves = [geo.addLine(point(piece[1]), point(piece[2])) if piece[0] == "line"
              else geo.addCircleArc(point(piece[1]), point(piece[2]), point(piece[3])) for piece in pieces]
    return geo.addCurveLoop(curves), curves


def _mesh(outline: list, holes: tuple, slots: list, mesh_size: float, meshing: QuadMeshing):
    """Mesh with gmsh: `(meshio.Mesh with physical groups, movable nodes)`."""
    try:
        import gmsh
    except ImportError:
        raise ImportError("link_profile meshes with gmsh: install it (pip install gmsh).") from None
    import meshio

    initialised = gmsh.isInitialized()
    if not initialised:
        gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("ffr_jax_link_profile")
        geo, points = gmsh.model.geo, {}
        outer, outline_curves = _loop(geo, outline, points)
        cutouts, rim_surfaces, bores, slot_curves, circles = [], [], {}, [], []
        for h in holes:
            bore, bores[h.name] = _loop(geo, _circle(h.centre, h.radius), points)
            circles.append((h.radius, bores[h.name]))
            if h.rim > 0:
                ring, ring_curves = _loop(geo, _circle(h.centre, h.radius + h.rim), points)
                circles.append((h.radius + h.rim, ring_curves))
                rim_surfaces.append(geo.addPlaneSurface([ring, bore]))
                cutouts.append(ring)
            else:
                cutouts.append(bore)
        for pieces in slots:
            loop, curves = _loop(geo, pieces, points)
            cutouts.append(loop)
            slot_curves += curves
        design = geo.addPlaneSurface([outer, *cutouts])
        geo.synchronize()
        for radius, curves in circles:
            ends = gmsh.model.getBoundary([(1, c) for c in curves], combined=False, oriented=False)
            gmsh.model.mesh.setSize(ends, min(2 * mesh_size, 2 * np.pi * radius / meshing.circle_points))
        groups = [(2, [design], "design"), (1, outline_curves, "outline")]
        groups += [(2, rim_surfaces, "rims")] if rim_surfaces else []
        groups += [(1, slot_curves, "slots")] if slot_curves else []
        groups += [(1, curves, f"bore_{name}") for name, curves in bores.items()]
        for dim, tags, name in groups:
            gmsh.model.addPhysicalGroup(dim, tags, name=name)
        for key, value in (("Mesh.MeshSizeMax", 2 * mesh_size),
                           ("Mesh.Algorithm", meshing.algorithm), ("Mesh.RecombineAll", 1),
                           ("Mesh.RecombinationAlgorithm", 1), ("Mesh.SubdivisionAlgorithm", 1),
                           ("Mesh.Smoothing", 10), ("Mesh.ElementOrder", 1), ("General.NumThreads", 1)):
            gmsh.option.setNumber(key, value)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(tags.size)
        xy = coords.reshape(-1, 3)[:, :2].copy()
        movable = np.zeros(tags.size, dtype=bool)
        cells, physical = [], []
        for tag, (dim, entities, name) in enumerate(groups, start=1):
            for entity in entities:
                if dim == 2:
                    inner, _, _ = gmsh.model.mesh.getNodes(2, entity, includeBoundary=False)
                    movable[index[inner.astype(np.int64)]] = True
                types, _, nodes = gmsh.model.mesh.getElements(dim, entity)
                wanted = {2: (3, "quad", 4), 1: (1, "line", 2)}[dim]
                if any(int(t) != wanted[0] for t in types):
                    raise RuntimeError(f"gmsh left elements other than {wanted[1]}s on {name!r} (types "
                                       f"{sorted(int(t) for t in types)}); this recipe should not: report the "
                                       "shape, and try another QuadMeshing(algorithm=...).")
                cells.append((wanted[1], index[np.asarray(nodes[0], dtype=np.int64)].reshape(-1, wanted[2])))
                physical.append(np.full(len(cells[-1][1]), tag, dtype=np.int64))
        gmsh.model.remove()
    finally:
        if not initialised:
            gmsh.finalize()
    field_data = {name: np.array([tag, dim]) for tag, (dim, _, name) in enumerate(groups, start=1)}
    mesh = meshio.Mesh(np.column_stack([xy, np.zeros(len(xy))]), cells,
                       cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical}, field_data=field_data)
    return mesh, movable


def link_profile(outline, holes, slots=(), *, fillet=0.0, mesh_size: float, meshing: QuadMeshing = QuadMeshing(),
                 path=None) -> PlanarGroups:
    """Mesh a planar part in quadrilaterals with gmsh: an outline with fillets, pin holes with passive rims, slots.

    The outline is the polygon `outline` with its corners rounded by `fillet`; a fillet of half an edge's length
    on both its corners uses the edge up (a rectangle of width `w` with `fillet=w/2` has semicircular ends). The
    part is meshed with the recipe of the module docstring: every element a quadrilateral, the corner-Jacobian
    ratios `min det J / max det J` raised by a guarded node relocation and refused below
    `meshing.min_jacobian_ratio`.

    **Arguments:**
    - `outline`: `(n, 2)` corners of the outline, in order around it (either direction), `n >= 3`.
    - `holes`: [`Hole`][]s (centre, radius, rim width, name), at least one.
    - `slots`: [`Slot`][]s (centre, length, width, corner radius, angle).
    - `fillet`: corner radius of the outline, one for all corners or one per corner.
    - `mesh_size`: target element size (an element's edge); at most each rim's width.
    - `meshing`: [`QuadMeshing`][] options; `path`: also write the mesh with its groups to this `.msh` file (gmsh
      2.2, which [`read_planar_groups`][] reads back to the same mesh and groups).

    **Returns:** the [`PlanarGroups`][] of the part: physical surfaces `"design"` and `"rims"` (the passive solid
    rings, if any hole has one); physical curves `"bore_<name>"` (each hole's edge: its nodes are the interface
    or marker of a pin), `"outline"` and `"slots"` (if any). The design domain is
    [`DesignDomain.from_groups`][]`(groups, solid="rims")`.

    **Raises** `ValueError` at once (before gmsh runs) for an outline that crosses itself, fillets that do not fit,
    a feature outside the outline or within `mesh_size` of the outline or of another feature, a rim narrower than
    `mesh_size`.
    """
    if not (isinstance(mesh_size, (int, float)) and np.isfinite(mesh_size) and mesh_size > 0):
        raise ValueError(f"mesh_size must be a positive number, got {mesh_size!r}.")
    if not isinstance(meshing, QuadMeshing):
        raise TypeError(f"meshing must be a QuadMeshing, got {type(meshing).__name__}.")
    if path is not None and pathlib.Path(path).suffix != ".msh":
        raise ValueError(f"path must name a .msh file (gmsh 2.2 keeps the physical groups), got {str(path)!r}.")
    corners, clockwise = _polygon(outline, "outline")
    fillet = np.asarray(fillet, dtype=np.float64)
    if fillet.shape not in ((), (len(corners),)):
        raise ValueError(f"fillet must be one radius or one per corner ({len(corners)}), got shape {fillet.shape}.")
    fillet = np.broadcast_to(fillet, (len(corners),))
    outline = _rounded(corners[::-1], fillet[::-1], "outline") if clockwise else _rounded(corners, fillet, "outline")
    holes = _holes(holes, float(mesh_size))
    slots = [_slot_pieces(s if isinstance(s, Slot) else Slot(*s)) for s in slots]
    _check_layout(outline, holes, slots, float(mesh_size))
    mesh, movable = _mesh(outline, holes, slots, float(mesh_size), meshing)
    elements = np.concatenate([b.data for b in mesh.cells if b.type == "quad"])
    xy = mesh.points[:, :2]
    clockwise = np.all(_corner_jacobians(xy[elements]) < 0, axis=1)  # gmsh orients elements along the normal
    elements[clockwise] = elements[clockwise][:, ::-1]
    if meshing.passes:
        mesh.points[:, :2] = relocate_nodes(xy, elements, movable, meshing.target_ratio, meshing.passes)
    ratios = jacobian_ratios(mesh.points[:, :2][elements])
    if ratios.min() < meshing.min_jacobian_ratio:
        worst = mesh.points[elements[ratios.argmin()], :2].mean(axis=0)
        raise ValueError(f"link_profile: {np.count_nonzero(ratios < meshing.min_jacobian_ratio)} elements have a "
                         f"corner-Jacobian ratio below {meshing.min_jacobian_ratio} (worst {ratios.min():.3g}, near "
                         f"({worst[0]:.4g}, {worst[1]:.4g})); give a smaller mesh_size, more relocation passes "
                         "(QuadMeshing(passes=...)), or a lower QuadMeshing(min_jacobian_ratio=...) if you accept the "
                         "loss of accuracy.")
    groups = planar_groups_from_meshio(mesh, meshing.min_jacobian_ratio)
    if path is not None:
        import meshio

        meshio.write(path, mesh, file_format="gmsh22", binary=False)
    return groups
