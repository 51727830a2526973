"""An animation of the mechanism in motion, the flexible body drawn deformed and coloured by density."""

import math
import shutil
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.body_data import marker_node_sets
from .._scene._point_on_line import PointOnLine
from .._scene._prescribed_point import CrankPin
from .._dynamics._simulate import solve_minimal


class Animation(NamedTuple):
    """What [`animate`][] wrote: the file, the number of frames, the amplification of the elastic
    displacements and the largest elastic displacement (in m, before amplification)."""

    path: Path
    frames: int
    amplification: float
    max_displacement: float


def _nice(value: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above `value` (a readable amplification factor)."""
    if not value > 0.0 or not math.isfinite(value):
        return 1.0
    exponent = math.floor(math.log10(value))
    mantissa = value / 10**exponent
    return float((5 if mantissa >= 5 else 2 if mantissa >= 2 else 1) * 10**exponent)


def body_motion(case: Case, x_phys, ts, *, rtol: float = 1e-8, atol: float = 1e-12):
    """The motion of the designed body at times `ts`: node positions with and without elasticity.

    Simulates the case for the physical densities `x_phys` (output at `ts`), recovers the
    redundant coordinates `(R, theta, q)` of the body at each time (the dependent ones by the
    model's Newton solve) and returns, per frame, the undeformed-body placement
    `R + A(theta) c_n` of every node `n` and the elastic displacement `A(theta) Phi_n q` in the
    inertial frame, from the modes the simulation used.

    **Returns:** `(rigid, elastic, y_r)`: `(n_t, n_nodes, 2)`, `(n_t, n_nodes, 2)` and `(n_t, n_r)`.
    """
    x_phys = case.design.check(jnp.asarray(x_phys, dtype=float))
    rigid, elastic, y_r = _motion(case, x_phys, jnp.asarray(ts, dtype=float), rtol, atol)
    return np.asarray(rigid), np.asarray(elastic), np.asarray(y_r)


@eqx.filter_jit
def _motion(case: Case, x_phys, ts, rtol: float, atol: float):
    """[`body_motion`][] as one compiled program (op by op, the modal analysis and the vmapped Newton
    solves take tens of seconds of dispatch)."""
    problem = case.problem_for(x_phys)
    scene = problem.scene
    modes = case.modes(x_phys).modes.reshape(case.mesh.n_nodes, 2, -1)
    trajectory = solve_minimal(problem.model, scene, problem.t0, problem.t1, problem.y0, problem.z0, ts=ts, rtol=rtol,
                               atol=atol, jump_ts=problem.jump_ts, dt0=problem.dt0)
    y_r = trajectory.positions
    offset = scene.offsets[designed_body_index(case)]
    nodes = jnp.asarray(case.mesh.nodes)

    def place(y):
        r, theta, q = y[offset:offset + 2], y[offset + 2], y[offset + 3:offset + 3 + modes.shape[2]]
        rotation = jnp.array([[jnp.cos(theta), -jnp.sin(theta)], [jnp.sin(theta), jnp.cos(theta)]])
        return r + nodes @ rotation.T, (modes @ q) @ rotation.T

    rigid, elastic = jax.vmap(place)(y_r)
    return rigid, elastic, y_r


def animate(case: Case, x_phys, path, *, frames: int = 60, fps: float = 20.0,
            amplification: float | None = None, rtol: float = 1e-8, atol: float = 1e-12, dpi: int = 100,
            title: str | None = None) -> Animation:
    """Write an animation of the case's mechanism over `[t0, t1]`: the designed body drawn deformed,
    its elements coloured by physical density, the crank and the slider guide drawn from the scene.

    The elastic displacements `A(theta) Phi q` are tiny next to the rigid motion, so they are
    multiplied by `amplification` (default: a 1-2-5 number that makes the largest one about 5 % of
    the larger side of the body's bounding box); every frame states the factor and the time. Frames are drawn with
    matplotlib (Agg) and written as a GIF with Pillow, or as an MP4 through `ffmpeg` when `path`
    ends in `.mp4` (only if `ffmpeg` is on `PATH`).

    **Arguments:**
    - `case`: the case; `x_phys`: `(n_design,)` physical densities (e.g. `design.npz["x_phys"]`).
    - `path`: `.gif` (or `.mp4`).
    - `frames`: number of frames, at times `linspace(t0, t1, frames)`; `fps`: frames per second.
    - `amplification`: factor on the elastic displacements (`None`: automatic).
    - `rtol`, `atol`: tolerances of the simulation; `dpi`: resolution; `title`: first line of the
      caption.

    **Returns:** an `Animation`.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    # Every input is checked before the simulation runs.
    path = Path(path)
    body = designed_body_index(case)
    if not (isinstance(frames, (int, np.integer)) and frames >= 1):
        raise ValueError(f"An animation needs a whole number of frames, at least one, got frames={frames!r}.")
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0.0):
        raise ValueError(f"The frame rate must be a positive number of frames per second, got fps={fps!r}.")
    if amplification is not None and not (math.isfinite(amplification) and amplification > 0.0):
        raise ValueError(f"The amplification must be a positive number (or None: automatic), got {amplification}.")
    if path.suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"Write the animation as .gif (Pillow) or .mp4 (ffmpeg), got {path.name}.")
    if path.suffix.lower() == ".mp4" and shutil.which("ffmpeg") is None:
        raise ValueError("MP4 output needs ffmpeg on PATH, which this machine lacks; write a .gif instead.")
    x_phys = np.asarray(case.design.check(jnp.asarray(x_phys, dtype=float)))
    ts = np.linspace(case.t0, case.t1, frames)
    rigid, elastic, _ = body_motion(case, x_phys, ts, rtol=rtol, atol=atol)
    largest = float(np.max(np.linalg.norm(elastic, axis=-1)))
    size = body_size(case.mesh)
    if amplification is None:
        amplification = _nice(0.05 * size / largest) if largest > 0.0 else 1.0
    positions = rigid + amplification * elastic
    quads = np.asarray(case.mesh.elements)
    density = np.asarray(case.design.element_densities(x_phys))
    decorations = _decorations(case, body, ts, rigid + elastic, size)
    everything = [positions.reshape(-1, 2)] + [points.reshape(-1, 2) for points, _ in decorations]
    low, high = np.min(np.concatenate(everything), axis=0), np.max(np.concatenate(everything), axis=0)
    margin = 0.08 * max(high - low)
    low, high = low - margin, high + margin

    figure = Figure(figsize=(8, 8 * max(0.3, (high[1] - low[1]) / (high[0] - low[0])) + 0.8), dpi=dpi)
    FigureCanvasAgg(figure)
    ax = figure.add_axes((0.1, 0.1, 0.76, 0.74))
    colour_axes = figure.add_axes((0.89, 0.15, 0.025, 0.7))
    cells = PolyCollection(positions[0][quads], array=density, cmap="gray_r", clim=(0.0, 1.0), edgecolors="face",
                           linewidths=0.3)
    ax.add_collection(cells)
    figure.colorbar(cells, cax=colour_axes, label="physical density")
    artists = [ax.plot([], [], style, lw=lw, ms=ms)[0] for _, (style, lw, ms) in decorations]
    ax.set_xlim(low[0], high[0])
    ax.set_ylim(low[1], high[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    caption = ax.set_title("")
    head = title or f"{case.design_map.names[0]}: {case.mesh.n_elements} elements"

    images = []
    writer = None
    if path.suffix.lower() == ".mp4":
        from matplotlib.animation import FFMpegWriter

        writer = FFMpegWriter(fps=fps)
        writer.setup(figure, str(path), dpi=dpi)
    try:
        for i, t in enumerate(ts):
            cells.set_verts(positions[i][quads])
            for artist, (points, _) in zip(artists, decorations, strict=True):
                artist.set_data(points[i, :, 0], points[i, :, 1])
            caption.set_text(f"{head}\nt = {t:.3f} s, elastic displacement x {amplification:g} "
                             f"(largest {1e3 * largest:.3g} mm)")
            if writer is not None:
                writer.grab_frame()
                continue
            figure.canvas.draw()
            images.append(_image(figure))
    finally:
        if writer is not None:
            writer.finish()
    if writer is None:
        images[0].save(path, save_all=True, append_images=images[1:], duration=int(round(1000.0 / fps)), loop=0)
    return Animation(path, frames, float(amplification), largest)


def designed_body_index(case: Case) -> int:
    """The scene index of the case's one designed body."""
    return case.scene_template.body_index(case.design_map.names[0]) if len(case.design_map.names) == 1 else \
        _one_body_error(case)


def _one_body_error(case):
    raise ValueError(f"The animation draws one designed body; this case has {len(case.design_map.names)} "
                     f"({list(case.design_map.names)}).")


def _image(figure):
    from PIL import Image

    rgba = np.asarray(figure.canvas.buffer_rgba())
    return Image.fromarray(rgba[..., :3].copy()).convert("P", palette=Image.Palette.ADAPTIVE, colors=255)


def body_size(mesh) -> float:
    """The larger side of the bounding box of a mesh's nodes (the scale of pictures of the body)."""
    return float(np.max(np.ptp(np.asarray(mesh.nodes), axis=0)))


def marker_path(case: Case, nodes, marker: int):
    """The joint point `marker` of the designed body per frame, `(n_t, 2)`: its node, or the centroid of
    its node set (e.g. a rim), from the node positions `nodes` `(n_t, n_nodes, 2)`."""
    node_set = marker_node_sets(case.mesh, case.marker_nodes)[marker]
    return nodes[:, list(node_set)].mean(axis=1)


def _decorations(case: Case, body: int, ts, nodes, size: float):
    """Lines to draw beside the body, from the scene's joints: `[(points (n_t, k, 2), (style, lw, ms))]`.

    A [`CrankPin`][] is drawn as the crank from its centre to the pin; a [`PointOnLine`][] as its
    guide line (fixed) and the slider's block at the joint point of the body (`nodes`: the true
    node positions per frame, `(n_t, n_nodes, 2)`; `body`: the designed body's scene index;
    `size`: the body's size, for the guide's reach).
    """
    scene = case.scene_template
    items = []
    ts = jnp.asarray(ts, dtype=float)
    for joint in scene.constraints:
        if isinstance(joint, CrankPin):
            pins = np.asarray(jax.vmap(joint.pin)(ts))
            centre = np.broadcast_to(np.asarray(joint.centre), pins.shape)
            items.append((np.stack([centre, pins], axis=1), ("C3o-", 3.0, 5.0)))
        elif isinstance(joint, PointOnLine):
            point, direction = np.asarray(joint.point), np.asarray(joint.direction)
            # The guide spans where the joint point travels, and a tenth of the body beyond.
            along = (marker_path(case, nodes, joint.marker) - point) @ direction if joint.body == body \
                else np.zeros(1)
            reach = 0.1 * size
            guide = np.stack([point + (along.min() - reach) * direction, point + (along.max() + reach) * direction])
            items.append((np.broadcast_to(guide, (len(ts), 2, 2)), ("k--", 0.8, 0.0)))
            if joint.body == body:
                items.append((marker_path(case, nodes, joint.marker)[:, None], ("C0s", 0.0, 8.0)))
    return items
