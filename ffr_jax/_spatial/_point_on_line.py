"""Point-on-line joint: a marker of a spatial body slides on an inertial line."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from ._revolute import normals, unit_axis
from ._spherical import ground_point, require_spatial


class SpatialPointOnLine(AbstractConstraint):
    """Marker `marker` of spatial body `body` stays on the inertial line through `point` along `direction`.

    Two equations, `c = [b_1, b_2] (r_P - point)` with `b_1, b_2` unit normals of the line; the body turns and
    slides freely along the line (a massless slider with a ball joint).

    **Arguments:**
    - `body`, `marker`: the sliding body and its marker; `point`: `(3,)` a point of the line;
    - `direction`: `(3,)` the line's direction (a `ValueError` for zero length).
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    point: jnp.ndarray
    normals: jnp.ndarray

    def __init__(self, body: int, marker: int, point=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0)):
        self.body, self.marker = int(body), int(marker)
        self.point = ground_point(point, "SpatialPointOnLine")
        self.normals = jnp.asarray(normals(unit_axis(direction, "SpatialPointOnLine direction")))

    @property
    def n_equations(self) -> int:
        return 2

    def residual(self, t, y_r, scene):
        del t
        require_spatial(scene, (self.body,), "SpatialPointOnLine")
        return self.normals @ (scene.marker_position(self.body, self.marker, y_r) - self.point)
