"""The outline of a design for CAD: the iso-contour of the physical density as SVG or DXF."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._case import Case


def density_outline(case: Case, x_phys, level: float = 0.5) -> list[np.ndarray]:
    """The closed boundaries of the region where the physical density is at least `level`, in body coordinates.

    The element densities (interface columns solid) are taken as values at the element centres,
    extended to the boundary of the body with the value of the adjacent element, and the region
    `density >= level` of their bilinear interpolation is traced (filled contours of `contourpy`,
    marching squares). Where material meets the boundary of the body the outline runs along the
    boundary, with its corners (a solid rod gives exactly its rectangle); inside, a solid/void
    interface between two elements runs along their common edge, with corners cut by half an
    element. Outer boundaries and holes both appear; fill them with the even–odd rule.

    **Arguments:**
    - `case`: the case whose body the design shapes; `x_phys`: `(n_design,)` physical densities.
    - `level`: the iso-value (0.5: the middle between void and solid).

    **Returns:** a list of closed polylines `(n_i, 2)` in metres (first point repeated at the end).
    """
    import contourpy

    if not 0.0 < level < 1.0:
        raise ValueError(f"The iso-contour level must lie in (0, 1), got {level}.")
    mesh = case.mesh
    x_phys = np.asarray(x_phys, dtype=float)
    if x_phys.shape != (case.n_design,) or not np.all(np.isfinite(x_phys)):
        raise ValueError(f"The outline needs {case.n_design} finite physical densities, got shape {x_phys.shape}"
                         f"{'' if np.all(np.isfinite(x_phys)) else ' with NaN or inf'}.")
    # Densities below x_min (e.g. 0 for a drawn void) are drawn as given: only the 0.5 crossing matters here.
    domain = case.design.domain
    field = np.asarray(domain.element_densities(jnp.asarray(x_phys), case.material.x_min)).reshape(mesh.ny, mesh.nx)
    padded = np.pad(field, 1, mode="edge")
    x = np.concatenate([[0.0], (np.arange(mesh.nx) + 0.5) * mesh.dx, [mesh.length]])
    y = -0.5 * mesh.height + np.concatenate([[0.0], (np.arange(mesh.ny) + 0.5) * mesh.dy, [mesh.height]])
    generator = contourpy.contour_generator(x, y, padded, fill_type=contourpy.FillType.OuterOffset)
    loops = []
    for points, offsets in zip(*generator.filled(level, np.inf), strict=True):
        for start, stop in zip(offsets[:-1], offsets[1:], strict=True):
            loop = np.asarray(points[start:stop])
            if not np.array_equal(loop[0], loop[-1]):
                loop = np.vstack([loop, loop[:1]])
            loops.append(loop)
    return loops


def write_svg(path, case: Case, x_phys, *, level: float = 0.5) -> Path:
    """Write the `level` iso-contour of the physical density as an SVG path (millimetres).

    One `<path>` with a subpath per closed contour and `fill-rule="evenodd"` (holes stay open);
    `width`/`height` in mm and a `viewBox` in mm, `y` pointing up as in the body frame (the SVG is
    flipped on output). See [`density_outline`][].

    **Returns:** the path written.
    """
    path = Path(path)
    lines = density_outline(case, x_phys, level)
    mesh = case.mesh
    width, height = 1000.0 * mesh.length, 1000.0 * mesh.height
    subpaths = []
    for line in lines:
        mm = 1000.0 * line
        coordinates = " L ".join(f"{px:.4f} {height / 2 - py:.4f}" for px, py in mm[:-1])
        subpaths.append(f"M {coordinates} Z")
    svg = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:g}mm" height="{height:g}mm" '
        f'viewBox="0 0 {width:g} {height:g}">\n'
        f'  <title>0.5 iso-contour of the physical density, {mesh.nx} x {mesh.ny} elements, mm</title>\n'
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
