"""The spatial slider–crank with its crank pin offset along the pin axis: the rod tilts out of the crank's plane and
is loaded across its own plane as well (issue 27's worked example)."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._model import Partition
from .._dynamics._problem import Problem
from .._objective._compliance import Compliance
from .._objective._time_window import TimeWindow
from .._scene._body import Body
from .._scene._damping import ModalDamping
from .._scene._scene import Scene
from .._spatial._angle_driver import EulerNormalisation, SpatialAngleDriver
from .._spatial._point_on_line import SpatialPointOnLine
from .._spatial._revolute import SpatialRevolute
from .._spatial._universal import SpatialUniversal
from ._spatial_slider_crank import spatial_crank

_Z = (0.0, 0.0, 1.0)


def _rod_parameters(yaw, tilt):
    """Euler parameters of `A = A_z(yaw) A_y(tilt)`: the rod's `x`-axis `(cos t cos g, cos t sin g, -sin t)`, its
    `y`-axis `(-sin g, cos g, 0)` horizontal (at right angles to the crank axis `z`, as the universal joint holds
    it)."""
    cz, sz, cy, sy = jnp.cos(yaw / 2), jnp.sin(yaw / 2), jnp.cos(tilt / 2), jnp.sin(tilt / 2)
    return jnp.stack([cz * cy, -sz * sy, cz * sy, cy * sz])


def offset_slider_crank_guess(t, y, scene):
    """Rigid-body estimate of the dependent coordinates (rod `R, p`, then crank `R, p`): the crank turned by
    `phi(t)` about `z`, its pin at `P = (r cos phi, r sin phi, e)`, the rod's origin at `P`, B on the `x`-axis at
    `P_x + sqrt(l^2 - P_y^2 - e^2)`: the rod turned by the yaw `atan2(-P_y, B_x - P_x)` about `z` and tilted by the
    constant `asin(e / l)` about its own `y`-axis. `r`, `e` and `l` are read from the scene's markers."""
    del y
    phi = scene.constraints[1].angle(t)
    pin_marker = scene.bodies[1].data.marker_positions[1]
    radius, offset = pin_marker[0], pin_marker[2]
    length = scene.bodies[0].data.marker_positions[1, 0]
    pin = jnp.stack([radius * jnp.cos(phi), radius * jnp.sin(phi), offset + jnp.zeros_like(phi)])
    reach = jnp.sqrt(length**2 - pin[1] ** 2 - offset**2)
    rod_p = _rod_parameters(jnp.arctan2(-pin[1], reach), jnp.arcsin(offset / length))
    crank_p = jnp.stack([jnp.cos(phi / 2), jnp.zeros_like(phi), jnp.zeros_like(phi), jnp.sin(phi / 2)])
    return jnp.concatenate([pin, rod_p, jnp.zeros(3), crank_p])


def offset_slider_crank_problem(rod_data, eccentricity: float, pin_offset: float, law, t1: float, *,
                                damping_ratio: float = 0.0, average_from: float | None = None) -> Problem:
    """The slider–crank with the crank pin offset by `e = pin_offset` along the crank axis `z`.

    Bodies: 0 the rod (`rod_data`: a [`SpatialFlexibleBodyData`][] with markers A and B on its `x`-axis, the length
    `l` between them), 1 the crank (rigid, 0.1 kg, its pin marker at `(r, 0, e)`; its motion is prescribed). Joints:
    the crank's hinge to the ground about `z` at the origin, its angle `phi(t)` (`law`) and its Euler normalisation;
    a universal joint of the rod's marker A on the crank pin, its arms the crank axis `z` and the rod's `y`-axis
    (the rod turns on the pin, and tilts about its own `y`-axis); the rod's marker B on the `x`-axis (a piston pin
    in a ball joint on the slider); the rod's Euler normalisation. 4 + 2 + 1 equations fix the rod's 7 rigid
    coordinates, 5 + 1 + 1 the crank's: no redundant constraint, the independent coordinates are the rod's `q`.

    With `e != 0` the rod runs tilted out of the crank's plane by `asin(e / l)`, so the inertia loads in that plane
    have components across the rod's plane: its out-of-plane modes are excited (with `e = 0` the motion is the
    hinged scene's, and the mirror symmetry of a symmetric part leaves them unexcited).

    **Arguments:** `rod_data`; `eccentricity` the crank radius `r` (m); `pin_offset` `e` (m, `|e| < l`); `law` the
    crank angle; `t1` the end time (s); `damping_ratio` of [`ModalDamping`][] on the rod (0: none); `average_from`:
    `None` for the compliance of the rod integrated over `[0, t1]` (paper eq. 49), or a time `t_a` for its average
    over `[t_a, t1]` ([`TimeWindow`][]).

    **Returns:** a [`Problem`][].
    """
    rod = Body("rod", rod_data)
    mass, radius, offset = 0.1, float(eccentricity), float(pin_offset)
    length = float(rod_data.marker_positions[1, 0])
    if not abs(offset) < length:
        raise ValueError(f"The crank pin offset must be shorter than the rod (|e| < l = {length}), got {offset}.")
    crank = spatial_crank(radius, offset, mass)
    forces = (ModalDamping(0, damping_ratio),) if damping_ratio > 0 else ()
    scene = Scene(
        bodies=(rod, crank),
        constraints=(
            SpatialRevolute(1, 0, _Z),
            SpatialAngleDriver(1, _Z, law),
            EulerNormalisation(1),
            SpatialUniversal(0, 0, (0.0, 1.0, 0.0), body_j=1, marker_j=1, axis_j=_Z),
            SpatialPointOnLine(0, 1, direction=(1.0, 0.0, 0.0)),
            EulerNormalisation(0),
        ),
        forces=forces,
    )
    n_q = rod.data.n_modes
    tilt = np.arcsin(offset / length)
    rod_p = np.array([np.cos(tilt / 2), 0.0, np.sin(tilt / 2), 0.0])
    positions = np.concatenate([[radius, 0.0, offset], rod_p, np.zeros(n_q), np.zeros(3), [1.0, 0.0, 0.0, 0.0]])
    independent = tuple(range(7, 7 + n_q))
    partition = Partition(independent=independent,
                          dependent=tuple(i for i in range(scene.n_coordinates) if i not in independent))
    objective, jump_ts = Compliance(body=0), scene.breakpoints
    if average_from is not None:
        if not 0.0 <= float(average_from) < t1:
            raise ValueError(f"average_from must lie in [0, t1) = [0, {t1}) (the start of the averaging window in "
                             f"s), got {average_from}.")
        objective = TimeWindow(objective, float(average_from), t1)
        jump_ts = tuple(sorted({*jump_ts, float(average_from)}))
    return Problem(scene, t1, positions=positions, objective=objective, partition=partition, jump_ts=jump_ts,
                   dependent_guess=offset_slider_crank_guess)
