"""Spherical joint between markers of two spatial bodies, or of one body and a ground point."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._scene._base import AbstractConstraint
from ._body_data import SpatialBodyData
from ._flexible_body_data import SpatialFlexibleBodyData


def ground_point(point, name: str):
    """A finite `(3,)` ground point, or a `ValueError` naming the joint."""
    value = np.asarray(point, dtype=float)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise ValueError(f"{name} ground point must be a finite (3,) vector, got {point!r}.")
    return jnp.asarray(value)


def require_spatial(scene, bodies, name: str) -> None:
    """A `ValueError` (at trace time) when one of `bodies` (ground: negative) is not a spatial body."""
    for b in bodies:
        if b >= 0 and not isinstance(scene.bodies[b].data, (SpatialBodyData, SpatialFlexibleBodyData)):
            raise ValueError(f"{name} joins spatial bodies, but body {b} ({scene.bodies[b].name!r}) is planar: give it "
                             "ffr_jax.spatial_rigid_body_data, or use the planar joints (Revolute, GroundRevolute).")


def other_point(joint, t, y_r, scene):
    """The inertial position of the joint's second point: marker `marker_j` of `body_j`, or the ground point."""
    del t
    if joint.body_j < 0:
        return joint.point
    return scene.marker_position(joint.body_j, joint.marker_j, y_r)


class SphericalJoint(AbstractConstraint):
    """Marker `marker_i` of body `body_i` coincides with marker `marker_j` of body `body_j` (a ball joint).

    `c = r_i(P) - r_j(Q)`, three equations; `body_j = -1` (the default) holds the marker at the inertial
    point `point` instead.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, body_j: int = -1, marker_j: int = 0, point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        self.point = ground_point(point, "SphericalJoint")

    @property
    def n_equations(self) -> int:
        return 3

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SphericalJoint")
        return scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
