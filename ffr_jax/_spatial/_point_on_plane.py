"""Point-on-plane joint: a marker of a spatial body slides on an inertial plane."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from ._revolute import unit_axis
from ._spherical import ground_point, require_spatial


class SpatialPointOnPlane(AbstractConstraint):
    """Marker `marker` of spatial body `body` stays on the inertial plane through `point` with normal `normal`.

    One equation, `c = n . (r_P - point)`. It is the slider of a mechanism whose motion a hinge already keeps in a
    plane (a spatial slider–crank with its hinges parallel): the slider's line is the plane's trace in the plane of
    motion, and a [`SpatialPointOnLine`][] there would repeat the hinge's equation (a rank-deficient Jacobian).

    **Arguments:**
    - `body`, `marker`: the sliding body and its marker; `point`: `(3,)` a point of the plane;
    - `normal`: `(3,)` the plane's normal (a `ValueError` for zero length).
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    point: jnp.ndarray
    normal: jnp.ndarray

    def __init__(self, body: int, marker: int, point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0)):
        self.body, self.marker = int(body), int(marker)
        self.point = ground_point(point, "SpatialPointOnPlane")
        self.normal = jnp.asarray(unit_axis(normal, "SpatialPointOnPlane normal"))

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        del t
        require_spatial(scene, (self.body,), "SpatialPointOnPlane")
        return (self.normal @ (scene.marker_position(self.body, self.marker, y_r) - self.point))[None]
