"""Pictures of a design and of a run (matplotlib; for the CLI and notebooks, never traced)."""

import numpy as np

from .._dynamics._case import Case
from .._design.mesh import StructuredGrid
from ._gradient_plot import plot_field
from ._history import History


def plot_design(case: Case, x_phys, ax=None, *, title: str | None = None):
    """Draw the physical densities over the whole rod (interface columns solid), as in the paper
    (over the elements of any other mesh with `ffr_jax.plot_field`).

    **Arguments:**
    - `case`: the case whose rod the design shapes; `x_phys`: `(n_design,)` physical densities.
    - `ax`: a matplotlib `Axes` (a new figure when `None`); `title`: optional title.

    **Returns:** the `Axes`.
    """
    from matplotlib.figure import Figure

    mesh = case.mesh
    if not isinstance(mesh, StructuredGrid):  # any other mesh: the elements drawn one by one
        return plot_field(case, x_phys, ax, title=title)
    if ax is None:
        ax = Figure(figsize=(10, 2.2), layout="constrained").subplots()
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


def plot_designs(case: Case, x_phys: dict, *, title: str | None = None):
    """Draw the physical densities of every designed rod of a case, one above the other, to scale.

    **Arguments:**
    - `case`: a case with designed bodies, e.g. `ffr_jax.cases.four_bar_two_links` (rods on a
      `StructuredGrid` are drawn as images, bodies on any other mesh element by element with
      [`plot_field`][]); `x_phys`: `{name: (n_design_b,)}` physical densities.
    - `title`: optional figure title.

    **Returns:** the matplotlib `Figure`.
    """
    from matplotlib.figure import Figure

    names = case.design_map.names
    missing = [n for n in names if n not in x_phys]
    if missing:
        raise ValueError(f"plot_designs: no densities for the designed bodies {missing}.")
    fig = Figure(figsize=(10, 1.5 * len(names) + 0.7), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(names), 1))
    width = max(np.ptp(case.design_map.bodies[n].mesh.nodes[:, 0]) for n in names)
    image = None
    for ax, name in zip(axes, names):
        body = case.design_map.bodies[name]
        mesh = body.mesh
        if not isinstance(mesh, StructuredGrid):  # any other mesh: its elements drawn one by one
            plot_field(body, np.asarray(x_phys[name]), ax,
                       title=f"{name}: mean density {float(np.mean(x_phys[name])):.3f}")
            continue
        field = np.asarray(body.element_densities(np.asarray(x_phys[name]))).reshape(mesh.ny, mesh.nx)
        image = ax.imshow(field, origin="lower", cmap="gray_r", vmin=0.0, vmax=1.0, interpolation="nearest",
                          aspect="auto", extent=(0.0, mesh.length, -0.5 * mesh.height, 0.5 * mesh.height))
        ax.set_xlim(0.0, width)
        ax.set_ylabel("y [m]")
        ax.set_title(f"{name}: mean density {float(np.mean(x_phys[name])):.3f}")
    axes[-1].set_xlabel("x [m]")
    if image is not None:
        fig.colorbar(image, ax=list(axes), label="density", fraction=0.03, pad=0.01)
    if title is not None:
        fig.suptitle(title)
    return fig


def plot_history(history: History, ax=None):
    """Draw `psi` per iteration (log scale when positive) and the largest design change (right
    axis); when the run had inequality constraints, their normalised values `g_i` in a second
    panel below (the feasible side `g <= 0` shaded).

    **Arguments:**
    - `history`: a run's [`History`][].
    - `ax`: a matplotlib `Axes` for `psi` (a new figure when `None`; the constraint panel is only
      drawn in a new figure, see [`plot_constraints`][] to draw it elsewhere).

    **Returns:** the `Axes` of `psi` (its `.figure` holds both panels).
    """
    from matplotlib.figure import Figure

    g = history.constraint_values
    if ax is None:
        if g.shape[1]:
            figure = Figure(figsize=(6.5, 6), layout="constrained")
            ax, below = figure.subplots(2, 1, sharex=True)
            plot_constraints(history, below)
        else:
            ax = Figure(figsize=(6, 3.5), layout="constrained").subplots()
    k = np.arange(history.steps)
    ax.plot(k, history.value, "C0.-", label="psi")
    if history.steps and np.all(history.value > 0):
        ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("psi", color="C0")
    right = ax.twinx()
    right.semilogy(k, np.maximum(history.change, 1e-16), "C1.-", label="max change")
    right.set_ylabel("max |x_new - x|", color="C1")
    return ax


def plot_constraints(history: History, ax=None):
    """Draw every constraint's normalised value `g_i(x_k)` per iteration, with the bound `g = 0`.

    `g = value / bound - 1` for an upper bound, `1 - value / bound` for a lower one, so the curves
    read as the relative distance to each bound (a symmetric-log axis keeps both the large start
    values and the approach to zero visible).

    **Returns:** the `Axes`.
    """
    from matplotlib.figure import Figure

    if ax is None:
        ax = Figure(figsize=(6.5, 3.5), layout="constrained").subplots()
    g = history.constraint_values
    k = np.arange(history.steps)
    for i, name in enumerate(history.names):
        ax.plot(k, g[:, i], ".-", color=f"C{i + 2}", label=f"g_{name}")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axhspan(ax.get_ylim()[0] if g.size and g.min() < 0 else -1e-3, 0.0, color="0.9", zorder=0)
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_xlabel("iteration")
    ax.set_ylabel("g (feasible <= 0)")
    if history.names:
        ax.legend(loc="best", fontsize="small")
    return ax
