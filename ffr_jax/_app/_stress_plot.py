"""A picture of an element field of stresses (e.g. the peak von Mises stress over the motion)."""

import numpy as np

from .._dynamics._case import Case


def plot_peak_stress(target, values, ax=None, *, limit: float | None = None, vmax: float | None = None,
                     title: str | None = None, label: str = "peak von Mises stress [MPa]"):
    """Draw a stress per element (e.g. [`peak_von_mises`][]) over the mesh of a designed body, in MPa.

    A sequential colour map from 0 to `vmax` (default: the largest value, or `limit` if that is
    larger); elements whose value exceeds `limit` are outlined in red, and the limit is marked on
    the colour bar.

    **Arguments:**
    - `target`: a case with one designed body (`case.design`) or a [`DesignedBody`][].
    - `values`: `(n_elements,)` in Pa, in the mesh's element order; `ax`: a matplotlib `Axes`
      (a new figure when `None`).
    - `limit`: a stress limit in Pa to mark, or `None`; `vmax`: the top of the colour scale in Pa
      (to draw several designs on one scale); `title`, `label`: optional text.

    **Returns:** the `Axes`.
    """
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    body = target.design if isinstance(target, Case) else target
    mesh = body.mesh
    values = np.asarray(values, dtype=float)
    if values.shape != (mesh.n_elements,):
        raise ValueError(f"plot_peak_stress takes one value per element, shape ({mesh.n_elements},), got "
                         f"{values.shape} (ffr_jax.peak_von_mises gives them).")
    if not np.all(np.isfinite(values)):
        raise ValueError("plot_peak_stress: the stresses contain NaN or inf.")
    top = vmax if vmax is not None else max(float(values.max()), limit or 0.0)
    if ax is None:
        lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
        aspect = (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-300)
        ax = Figure(figsize=(9, max(2.0, 9 * aspect + 0.8)), layout="constrained").subplots()
    cells = PolyCollection(mesh.element_coordinates(), array=values / 1e6, cmap="inferno",
                           norm=Normalize(0.0, (top or 1.0) / 1e6), edgecolors="face", linewidths=0.2)
    ax.add_collection(cells)
    bar = ax.figure.colorbar(cells, ax=ax, label=label, fraction=0.04, pad=0.01)
    if limit is not None:
        bar.ax.axhline(limit / 1e6, color="tab:red", linewidth=2)
        over = values > limit
        if over.any():
            ax.add_collection(PolyCollection(np.asarray(mesh.element_coordinates())[over], facecolors="none",
                                             edgecolors="tab:red", linewidths=1.0))
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title is not None:
        ax.set_title(title)
    return ax
