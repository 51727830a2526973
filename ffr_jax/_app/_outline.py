"""The outline of a design for CAD: the iso-contour of the physical density as SVG or DXF."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.mesh import QuadMesh, StructuredGrid


def density_outline(case: Case, x_phys, level: float = 0.5) -> list[np.ndarray]:
    """The closed boundaries of the region where the physical density is at least `level`, in body coordinates.

    On any quadrilateral mesh (a gmsh part, the holed link): every element is split into four
    triangles about its centroid; the centroid carries the element's density, a node the
    area-weighted mean of the densities of the elements around it, and the region
    `density >= level` of the piecewise linear field is traced (`matplotlib`'s filled triangle
    contours). The outline runs along the mesh boundary (holes included) where material meets it;
    a fully solid part gives exactly its polygonal boundary.

    On a `StructuredGrid` (the rod) the element densities are values at the element centres,
    extended to the boundary with the value of the adjacent element, and the region of their
    bilinear interpolation is traced (marching squares, `contourpy`): a solid rod gives exactly its
    rectangle, and a solid/void interface between two elements runs along their common edge, with
    corners cut by half an element.

    Outer boundaries and holes both appear; fill them with the even–odd rule.

    **Arguments:**
    - `case`: the case whose body the design shapes; `x_phys`: `(n_design,)` physical densities.
    - `level`: the iso-value (0.5: the middle between void and solid).

    **Returns:** a list of closed polylines `(n_i, 2)` in metres (first point repeated at the end).
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"The iso-contour level must lie in (0, 1), got {level}.")
    x_phys = np.asarray(x_phys, dtype=float)
    if x_phys.shape != (case.n_design,) or not np.all(np.isfinite(x_phys)):
        raise ValueError(f"The outline needs {case.n_design} finite physical densities, got shape {x_phys.shape}"
                         f"{'' if np.all(np.isfinite(x_phys)) else ' with NaN or inf'}.")
    # Densities below x_min (e.g. 0 for a drawn void) are drawn as given: only the level crossing matters here.
    density = np.asarray(case.design.domain.element_densities(jnp.asarray(x_phys), case.material.x_min))
    if isinstance(case.mesh, StructuredGrid):
        loops = _grid_outline(case.mesh, density, level)
    else:
        loops = _quad_outline(case.mesh, density, level)
    return [loop if np.array_equal(loop[0], loop[-1]) else np.vstack([loop, loop[:1]]) for loop in loops]


def _grid_outline(mesh: StructuredGrid, density, level: float) -> list[np.ndarray]:
    """Marching squares over the element centres of a structured grid (see [`density_outline`][])."""
    import contourpy

    padded = np.pad(density.reshape(mesh.ny, mesh.nx), 1, mode="edge")
    x = np.concatenate([[0.0], (np.arange(mesh.nx) + 0.5) * mesh.dx, [mesh.length]])
    y = -0.5 * mesh.height + np.concatenate([[0.0], (np.arange(mesh.ny) + 0.5) * mesh.dy, [mesh.height]])
    generator = contourpy.contour_generator(x, y, padded, fill_type=contourpy.FillType.OuterOffset)
    loops = []
    for points, offsets in zip(*generator.filled(level, np.inf), strict=True):
        loops += [np.asarray(points[start:stop]) for start, stop in zip(offsets[:-1], offsets[1:], strict=True)]
    return loops


def _quad_outline(mesh: QuadMesh, density, level: float) -> list[np.ndarray]:
    """Filled triangle contours of the nodal-and-centroid field of any quad mesh (see [`density_outline`][])."""
    from matplotlib.figure import Figure
    from matplotlib.path import Path as MplPath
    from matplotlib.tri import Triangulation

    # Each quad is split into four triangles about its centroid, which carries the element's density; a
    # node carries the area-weighted mean of its elements' densities (so a fully solid part is 1 everywhere).
    areas = mesh.element_areas()
    weight = np.zeros(mesh.n_nodes)
    total = np.zeros(mesh.n_nodes)
    np.add.at(weight, mesh.elements, areas[:, None])
    np.add.at(total, mesh.elements, (areas * density)[:, None])
    nodal = total / weight
    centres = np.arange(mesh.n_elements) + mesh.n_nodes
    points = np.vstack([mesh.nodes, mesh.element_centroids()])
    values = np.concatenate([nodal, density])
    corners = mesh.elements
    triangles = np.concatenate([np.stack([centres, corners[:, k], corners[:, (k + 1) % 4]], axis=1)
                                for k in range(4)])
    if values.max() < level:
        return []
    top = float(values.max()) + 1.0  # above every value: the filled band [level, top] is {value >= level}
    contours = Figure().subplots().tricontourf(Triangulation(points[:, 0], points[:, 1], triangles), values,
                                               levels=[level, top])
    loops = []
    for path in contours.get_paths():
        starts = np.flatnonzero(path.codes == MplPath.MOVETO) if path.codes is not None else np.array([0])
        for start, stop in zip(starts, list(starts[1:]) + [len(path.vertices)], strict=True):
            loop = np.asarray(path.vertices[start:stop])
            if path.codes is not None and path.codes[stop - 1] == MplPath.CLOSEPOLY:
                loop = loop[:-1]  # CLOSEPOLY's vertex is a placeholder
            if len(loop) >= 3:
                loops.append(loop)
    return loops


def write_svg(path, case: Case, x_phys, *, level: float = 0.5) -> Path:
    """Write the `level` iso-contour of the physical density as an SVG path (millimetres).

    One `<path>` with a subpath per closed contour and `fill-rule="evenodd"` (holes stay open);
    `width`/`height` in mm and a `viewBox` in mm, `y` pointing up as in the body frame (the SVG is
    flipped on output); the drawing is the bounding box of the body's mesh, its left edge at the
    SVG's x = 0 and its top edge at the SVG's y = 0. See [`density_outline`][].

    **Returns:** the path written.
    """
    path = Path(path)
    lines = density_outline(case, x_phys, level)
    mesh = case.mesh
    low, high = 1000.0 * mesh.nodes.min(axis=0), 1000.0 * mesh.nodes.max(axis=0)
    width, height = high - low
    subpaths = []
    for line in lines:
        mm = 1000.0 * line
        coordinates = " L ".join(f"{px - low[0]:.4f} {high[1] - py:.4f}" for px, py in mm[:-1])
        subpaths.append(f"M {coordinates} Z")
    svg = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:g}mm" height="{height:g}mm" '
        f'viewBox="0 0 {width:g} {height:g}">\n'
        f'  <title>{level:g} iso-contour of the physical density, {mesh.n_elements} elements, mm</title>\n'
        f'  <path fill="black" fill-rule="evenodd" stroke="none" d="{" ".join(subpaths)}"/>\n'
        "</svg>\n"
    )
    path.write_text(svg)
    return path


def write_dxf(path, case: Case, x_phys, *, level: float = 0.5) -> Path:
    """Write the `level` iso-contour of the physical density as closed polylines of an ASCII DXF (R12, mm).

    One `POLYLINE` (closed, flag 70 = 1) with its `VERTEX` entities per contour, in the
    `ENTITIES` section of a minimal R12 file, body coordinates in millimetres.

    **Returns:** the path written.
    """
    path = Path(path)
    pairs = ["0", "SECTION", "2", "ENTITIES"]
    for line in density_outline(case, x_phys, level):
        pairs += ["0", "POLYLINE", "8", "OUTLINE", "66", "1", "70", "1", "10", "0.0", "20", "0.0", "30", "0.0"]
        for px, py in 1000.0 * line[:-1]:
            pairs += ["0", "VERTEX", "8", "OUTLINE", "10", f"{px:.6f}", "20", f"{py:.6f}", "30", "0.0"]
        pairs += ["0", "SEQEND", "8", "OUTLINE"]
    pairs += ["0", "ENDSEC", "0", "EOF"]
    path.write_text("\n".join(pairs) + "\n")
    return path
