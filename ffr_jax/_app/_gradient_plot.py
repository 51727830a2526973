"""Pictures of design fields: a gradient over the rod (paper Figs. 5–6), any field over any mesh
(matplotlib; for the CLI, notebooks and benchmarks)."""

import numpy as np

from .._dynamics._case import Case
from .._design.domain import SOLID
from .._design.mesh import StructuredGrid


def row_signs(case: Case, grad) -> list[dict]:
    """The sign pattern of a design gradient, row by row (REFERENCE_CASE §4: outer rows negative,
    inner rows positive in the paper).

    **Arguments:**
    - `case`: the case whose rod the design shapes; `grad`: `(n_design,)` gradient in design order.

    **Returns:** one dict per element row `j = 0..ny-1` (bottom to top) with the row's
    `y_min`, `y_max` [m], `n_negative`, `n_positive`, `min`, `max`, `mean`, and `sign`:
    `"-"` or `"+"` when every entry of the row has that sign, `"mixed"` otherwise.
    """
    mesh = case.mesh
    grid = case.design_grid(grad)
    rows = []
    for j, row in enumerate(grid):
        negative, positive = int(np.sum(row < 0)), int(np.sum(row > 0))
        sign = "-" if negative == row.size else "+" if positive == row.size else "mixed"
        rows.append({
            "row": j,
            "y_min": -0.5 * mesh.height + j * mesh.height / mesh.ny,
            "y_max": -0.5 * mesh.height + (j + 1) * mesh.height / mesh.ny,
            "n_negative": negative,
            "n_positive": positive,
            "min": float(row.min()),
            "max": float(row.max()),
            "mean": float(row.mean()),
            "sign": sign,
        })
    return rows


def plot_gradient(case: Case, grad, *, title: str | None = None, figure=None):
    """Draw a design gradient over the rod like the paper's Figs. 5–6: a surface above the design
    region of the rod's reference domain, and below it the same field as a signed colour map.

    The design region spans the element columns `1 .. nx-2` (the interface columns carry no design
    variable): `x` from `L/nx` to `L - L/nx` (0.01 … 0.99 m for the reference rod) and `y` from
    `-h/2` to `h/2`; each value sits at its element's centre. On any other mesh (a gmsh part, the
    holed link) the surface is triangulated over the design elements' centroids and the map below
    is [`plot_field`][]`(signed=True)`, passive elements grey.

    **Arguments:**
    - `case`: the case whose rod the design shapes; `grad`: `(n_design,)` gradient in design order.
    - `title`: optional title; `figure`: a matplotlib `Figure` to draw into (a new one when `None`).

    **Returns:** the `Figure`.
    """
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.figure import Figure

    mesh = case.mesh
    if not isinstance(mesh, StructuredGrid):
        return _plot_gradient_on_elements(case, grad, title=title, figure=figure)
    grid = case.design_grid(grad)
    centres = case.design.domain.design_centroids().reshape(mesh.ny, mesh.nx - 2, 2)
    xc, yc = centres[..., 0], centres[..., 1]
    scale = float(np.max(np.abs(grid))) or 1.0
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-scale, vmax=scale)

    if figure is None:
        figure = Figure(figsize=(10, 8), layout="constrained")
    grid_spec = figure.add_gridspec(2, 1, height_ratios=(3, 2))
    surface_ax = figure.add_subplot(grid_spec[0], projection="3d")
    surface_ax.plot_surface(xc, yc, grid, cmap="RdBu_r", norm=norm, rstride=1, cstride=1, linewidth=0.2,
                            edgecolor="k", antialiased=True)
    surface_ax.set_xlabel("x [m]")
    surface_ax.set_ylabel("y [m]")
    surface_ax.set_zlabel("dpsi/dx_e", labelpad=12)
    surface_ax.set_box_aspect((3.0, 1.0, 1.0), zoom=1.25)
    surface_ax.view_init(elev=25, azim=-60)
    if title is not None:
        surface_ax.set_title(title)

    map_ax = figure.add_subplot(grid_spec[1])
    dx = mesh.length / mesh.nx
    image = map_ax.imshow(
        grid, origin="lower", cmap="RdBu_r", norm=norm, interpolation="nearest", aspect="auto",
        extent=(dx, mesh.length - dx, -0.5 * mesh.height, 0.5 * mesh.height),
    )
    figure.colorbar(image, ax=map_ax, label="dpsi/dx_e", fraction=0.04, pad=0.01)
    map_ax.set_xlabel("x [m]")
    map_ax.set_ylabel("y [m]")
    map_ax.set_title(f"gradient over the design region ({mesh.ny} x {mesh.nx - 2} elements), "
                     f"max |grad| = {scale:.3e}")
    return figure


def _plot_gradient_on_elements(case: Case, grad, *, title: str | None, figure):
    """[`plot_gradient`][] on any mesh: a surface over the design elements' centroids (triangulated) above
    the signed field drawn element by element ([`plot_field`][], passive elements grey)."""
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.figure import Figure

    domain = case.design.domain
    grad = np.asarray(grad, dtype=float)
    if grad.shape != (domain.n_design,):
        raise ValueError(f"plot_gradient takes a vector of shape ({domain.n_design},), got {grad.shape}.")
    centres = domain.design_centroids()
    scale = float(np.max(np.abs(grad))) or 1.0
    if figure is None:
        figure = Figure(figsize=(10, 8), layout="constrained")
    grid_spec = figure.add_gridspec(2, 1, height_ratios=(3, 2))
    surface_ax = figure.add_subplot(grid_spec[0], projection="3d")
    surface_ax.plot_trisurf(centres[:, 0], centres[:, 1], grad, cmap="RdBu_r",
                            norm=TwoSlopeNorm(vcenter=0.0, vmin=-scale, vmax=scale), linewidth=0.1, edgecolor="k")
    surface_ax.set_xlabel("x [m]")
    surface_ax.set_ylabel("y [m]")
    surface_ax.set_zlabel("dpsi/dx_e", labelpad=12)
    span = np.ptp(case.mesh.nodes, axis=0)
    surface_ax.set_box_aspect((3.0, max(0.3, 3.0 * span[1] / max(span[0], 1e-300)), 1.0), zoom=1.1)
    surface_ax.view_init(elev=25, azim=-60)
    if title is not None:
        surface_ax.set_title(title)
    plot_field(case, grad, figure.add_subplot(grid_spec[1]), signed=True,
               title=f"gradient over the {domain.n_design} design elements (passive elements grey), "
                     f"max |grad| = {scale:.3e}")
    return figure


def plot_field(target, values, ax=None, *, title: str | None = None, signed: bool = False, label: str | None = None):
    """Draw a design-ordered field over the elements of any mesh (e.g. the holed link).

    Densities (`signed=False`): grey scale from 0 (white) to 1 (black), passive solid elements
    black and passive void white. Signed fields such as gradients (`signed=True`): a diverging
    map symmetric about zero, passive elements light grey (they carry no design variable).

    **Arguments:**
    - `target`: a case with one designed body (`case.design`) or a [`DesignedBody`][].
    - `values`: `(n_design,)` in design order; `ax`: a matplotlib `Axes` (a new figure when `None`).
    - `title`, `label` (colour bar): optional text.

    **Returns:** the `Axes`.
    """
    import matplotlib
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize, TwoSlopeNorm
    from matplotlib.figure import Figure

    body = target.design if isinstance(target, Case) else target
    domain, mesh = body.domain, body.mesh
    values = np.asarray(values, dtype=float)
    if values.shape != (domain.n_design,):
        raise ValueError(f"plot_field takes a vector of shape ({domain.n_design},), got {values.shape}.")
    roles = domain.role_array()
    if signed:  # passive elements carry no design variable: masked, drawn in the "bad" grey below
        field = np.full(roles.shape, np.nan)
    else:
        field = np.where(roles == SOLID, 1.0, 0.0)
    field[np.asarray(domain.design_elements)] = values
    if signed:
        scale = float(np.nanmax(np.abs(values))) or 1.0
        cmap, norm = "RdBu_r", TwoSlopeNorm(vcenter=0.0, vmin=-scale, vmax=scale)
    else:
        cmap, norm = "gray_r", Normalize(0.0, 1.0)
    if ax is None:
        lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
        aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-300)
        ax = Figure(figsize=(9, max(2.0, 9 * aspect + 0.8)), layout="constrained").subplots()
    cmap = matplotlib.colormaps[cmap].with_extremes(bad="0.85")  # the grey of elements without a design variable
    cells = PolyCollection(mesh.element_coordinates(), array=np.ma.masked_invalid(field), cmap=cmap, norm=norm,
                           edgecolors="face", linewidths=0.2)
    ax.add_collection(cells)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.figure.colorbar(cells, ax=ax, label=label or ("dpsi/dx_e" if signed else "density"), fraction=0.04, pad=0.01)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title is not None:
        ax.set_title(title)
    return ax
