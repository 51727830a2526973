"""Pictures of a design and of a run (matplotlib; for the CLI and notebooks, never traced)."""

import numpy as np

from .._case import Case
from ._history import History


def plot_design(case: Case, x_phys, ax=None, *, title: str | None = None):
    """Draw the physical densities over the whole rod (interface columns solid), as in the paper.

    **Arguments:**
    - `case`: the case whose rod the design shapes; `x_phys`: `(n_design,)` physical densities.
    - `ax`: a matplotlib `Axes` (a new figure when `None`); `title`: optional title.

    **Returns:** the `Axes`.
    """
    from matplotlib.figure import Figure

    if ax is None:
        ax = Figure(figsize=(10, 2.2), layout="constrained").subplots()
    mesh = case.mesh
    field = np.asarray(case.design.element_densities(np.asarray(x_phys))).reshape(mesh.ny, mesh.nx)
    image = ax.imshow(
        field, origin="lower", cmap="gray_r", vmin=0.0, vmax=1.0, interpolation="nearest", aspect="auto",
        extent=(0.0, mesh.length, -0.5 * mesh.height, 0.5 * mesh.height),
    )
    ax.figure.colorbar(image, ax=ax, label="density", fraction=0.04, pad=0.01)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title is not None:
        ax.set_title(title)
    return ax


def plot_history(history: History, ax=None):
    """Draw `psi` per iteration (log scale) and the largest design change (right axis).

    **Arguments:**
    - `history`: a run's [`History`][]; `ax`: a matplotlib `Axes` (a new figure when `None`).

    **Returns:** the `Axes` of `psi`.
    """
    from matplotlib.figure import Figure

    if ax is None:
        ax = Figure(figsize=(6, 3.5), layout="constrained").subplots()
    k = np.arange(history.steps)
    ax.plot(k, history.value, "C0.-", label="psi")
    if np.all(history.value > 0):
        ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("psi", color="C0")
    right = ax.twinx()
    right.semilogy(k, np.maximum(history.change, 1e-16), "C1.-", label="max change")
    right.set_ylabel("max |x_new - x|", color="C1")
    return ax
