"""The paper's slider–crank embedded in space: spatial bodies and joints, the rod's planar design lifted to 3D."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._model import Partition
from .._dynamics._problem import Problem
from .._objective._compliance import Compliance
from .._scene._body import Body
from .._scene._scene import Scene
from .._spatial._angle_driver import EulerNormalisation, SpatialAngleDriver
from .._spatial._body_data import spatial_rigid_body_data
from .._spatial._lift import uniform_lifted_body_data
from .._spatial._point_on_plane import SpatialPointOnPlane
from .._spatial._revolute import SpatialRevolute

_Z = (0.0, 0.0, 1.0)


def _half_turn(angle):
    """Euler parameters `(cos(a/2), 0, 0, sin(a/2))` of a turn by `a` about `z`."""
    half = 0.5 * angle
    zero = jnp.zeros_like(half)
    return jnp.stack([jnp.cos(half), zero, zero, jnp.sin(half)])


def spatial_slider_crank_guess(t, y, scene):
    """Rigid-body estimate of the dependent coordinates (rod `R, p`, then crank `R, p`): the crank turned by
    `phi(t)` about `z`, the rod's origin at the crank pin `P(t)` and the rod turned by `-asin(P_y / l)`.

    The crank radius and the rod length `l` are read from the scene (marker 1 of each body), as in the planar guess.
    """
    del y
    phi = scene.constraints[1].angle(t)
    radius = scene.bodies[1].data.marker_positions[1, 0]
    length = scene.bodies[0].data.marker_positions[1, 0]
    pin = jnp.stack([radius * jnp.cos(phi), radius * jnp.sin(phi), jnp.zeros_like(phi)])
    return jnp.concatenate([pin, _half_turn(-jnp.arcsin(pin[1] / length)), jnp.zeros(3), _half_turn(phi)])


def spatial_crank(radius: float, pin_offset: float = 0.0, mass: float = 0.1) -> Body:
    """The crank of the spatial slider-cranks: a slender rigid bar of `mass` along its x axis, from the bearing
    (marker 0, the origin) to the crank pin (marker 1, `(radius, 0, pin_offset)`), with a small regularising
    inertia about every axis."""
    return Body("crank", spatial_rigid_body_data(
        mass, (mass * radius / 2, 0.0, 0.0),
        np.diag([1e-6, mass * radius**2 / 3, mass * radius**2 / 3]) + 1e-6 * np.eye(3),
        [(0.0, 0.0, 0.0), (radius, 0.0, pin_offset)]))


def spatial_slider_crank_problem(rod_body, eccentricity: float, law, t1: float, rod_data=None) -> Problem:
    """The [`Problem`][] of `slider_crank(..., spatial=True)` (see there); `rod_body` is the planar designed rod
    (lifted), or `rod_data` the rod's [`SpatialFlexibleBodyData`][] (markers A and B on its x-axis; then `rod_body`
    is not used).

    Bodies: 0 the rod (lifted, coordinates `(R, p, q)`), 1 the crank (rigid, a slender bar of 0.1 kg from the
    hinge to the pin; its motion is prescribed, so its inertia does not enter the rod's motion). Joints: the crank's
    hinge to the ground about `z` at the origin, its angle `phi(t)` (the planar crank's law) and its Euler
    normalisation; the rod's hinge about `z` at A on the crank pin; B on the plane `y = 0` (the hinges keep
    everything in `z = 0`, so this is the slider on the x-axis; a point-on-line would repeat the hinge's `z`
    equation); the rod's Euler normalisation. Independent coordinates: the rod's `q`, as in the planar case.
    """
    rod = Body("rod", uniform_lifted_body_data(rod_body) if rod_data is None else rod_data)
    radius = float(eccentricity)
    crank = spatial_crank(radius)
    scene = Scene(
        bodies=(rod, crank),
        constraints=(
            SpatialRevolute(1, 0, _Z),
            SpatialAngleDriver(1, _Z, law),
            EulerNormalisation(1),
            SpatialRevolute(0, 0, _Z, body_j=1, marker_j=1, axis_j=_Z),
            SpatialPointOnPlane(0, 1, normal=(0.0, 1.0, 0.0)),
            EulerNormalisation(0),
        ),
    )
    n_q = rod.data.n_modes
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    positions = np.concatenate([[radius, 0.0, 0.0], identity, np.zeros(n_q), np.zeros(3), identity])
    independent = tuple(range(7, 7 + n_q))
    partition = Partition(independent=independent,
                          dependent=tuple(i for i in range(scene.n_coordinates) if i not in independent))
    return Problem(scene, t1, positions=positions, objective=Compliance(body=0), partition=partition,
                   dependent_guess=spatial_slider_crank_guess)
