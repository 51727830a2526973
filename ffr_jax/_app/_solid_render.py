"""Pictures of a solid design: the surface of the region where the density reaches a level, drawn in 3-D."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._design.solid_designed_body import SolidDesignedBody

# Faces of the VTK cells, outward for a positively numbered cell (the 10-node tetrahedron by its corners).
_FACES = {
    "hexahedron": ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
    "tetra10": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)),
}


def solid_surface(elements, cell_type: str, keep) -> np.ndarray:
    """The boundary faces of the set of elements `keep`: the faces that belong to exactly one kept element.

    **Arguments:** `elements` `(n_elements, nodes per element)` VTK order; `cell_type` `"hexahedron"` or
    `"tetra10"`; `keep` `(n_elements,)` booleans.

    **Returns:** `(n_faces, corners)` node indices of the faces, in the order of their element's outward numbering.
    """
    faces = np.asarray(_FACES[cell_type])
    kept = np.asarray(elements)[np.asarray(keep, dtype=bool)]
    if kept.shape[0] == 0:
        return np.zeros((0, faces.shape[1]), dtype=int)
    all_faces = kept[:, faces].reshape(-1, faces.shape[1])
    _, index, counts = np.unique(np.sort(all_faces, axis=1), axis=0, return_index=True, return_counts=True)
    return all_faces[np.sort(index[counts == 1])]


def plot_solid_design(body, x_phys, path=None, *, level: float = 0.5,
                      views: tuple = ((30.0, -70.0), (-30.0, 110.0)), title: str | None = None, dpi: int = 120):
    """Draw a solid design as a designer looks at it: the surface of the region where the element density reaches
    `level` (the passive regions included), shaded by the faces' orientation to a light, from one or more views.

    The region is the union of the elements whose physical density (passive solid ones: 1) is at least `level`;
    its surface the faces that belong to one such element only (for a crisp 0/1 design the part's boundary, hexahedral
    facets included). Design elements are drawn in steel blue, passive ones in grey. Matplotlib's `mplot3d` draws
    the faces in depth order (no true hidden-surface removal), which a part of a few thousand facets shows well.

    **Arguments:**
    - `body`: the designed solid body ([`SolidDesignedBody`][], e.g. `case.design`); `x_phys`: `(n_design,)`
      physical densities.
    - `path`: where to write the picture (PNG, ...), or `None`.
    - `level`: the density of the surface (default 0.5); `views`: `(elevation, azimuth)` pairs in degrees, one
      panel each; `title`; `dpi`.

    **Returns:** the matplotlib figure.
    """
    if not isinstance(body, SolidDesignedBody):
        raise ValueError("plot_solid_design draws a solid body (hexahedra or tetrahedra); for a planar body use "
                         "ffr_jax.plot_design.")
    if not 0.0 < float(level) < 1.0:
        raise ValueError(f"level must lie in (0, 1) (the density of the surface), got {level}.")
    views = tuple(views)
    if not views or any(len(v) != 2 for v in views):
        raise ValueError(f"views must be (elevation, azimuth) pairs in degrees, got {views!r}.")
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    mesh = body.mesh
    x_phys = body.check(jnp.asarray(x_phys, dtype=float))
    density = np.asarray(body.domain.element_densities(x_phys, body.material.x_min))
    design = np.isin(np.arange(mesh.n_elements), np.asarray(body.domain.design_elements))
    nodes = np.asarray(mesh.nodes)
    light = np.array([0.4, -0.5, 0.75]) / np.linalg.norm([0.4, -0.5, 0.75])
    n_views = len(views)
    figure = plt.figure(figsize=(8.0, 3.2 * n_views))
    for panel, (elevation, azimuth) in enumerate(views):
        axes = figure.add_axes((0.0, 1.0 - (panel + 1) / n_views, 1.0, 0.92 / n_views), projection="3d")
        for keep, colour in ((design & (density >= level), (0.27, 0.51, 0.71)), (~design, (0.62, 0.62, 0.62))):
            faces = solid_surface(mesh.elements, mesh.cell_type, keep)
            if not faces.shape[0]:
                continue
            polygons = nodes[faces]
            normals = np.cross(polygons[:, 1] - polygons[:, 0], polygons[:, 2] - polygons[:, 0])
            normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
            shade = 0.35 + 0.65 * np.abs(normals @ light)
            collection = Poly3DCollection(polygons, facecolors=np.clip(np.outer(shade, colour), 0, 1),
                                          edgecolors=(0, 0, 0, 0.15), linewidths=0.2)
            collection.set_clip_on(False)  # a 3-D axes draws in a square; the zoomed part is wider
            axes.add_collection3d(collection)
        low, high = nodes.min(axis=0), nodes.max(axis=0)
        for setter, a, b in zip((axes.set_xlim, axes.set_ylim, axes.set_zlim), low, high):
            setter(a, b)
        axes.set_box_aspect(tuple(high - low), zoom=2.4)  # equal scales in x, y, z
        axes.view_init(elev=elevation, azim=azimuth)
        axes.set_axis_off()
        axes.text2D(0.02, 0.9, f"view: elevation {elevation:g}, azimuth {azimuth:g}", fontsize=8,
                    transform=figure.transFigure if n_views == 1 else axes.transAxes)
    if title:
        figure.suptitle(title, fontsize=10)
    if path is not None:
        figure.savefig(Path(path), dpi=dpi)
    return figure
