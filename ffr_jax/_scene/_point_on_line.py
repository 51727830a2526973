"""Point-on-line joint: a massless, frictionless slider on an inertial line."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractConstraint
from ._references import finite_vector


class PointOnLine(AbstractConstraint):
    """Marker `marker` of body `body` stays on the line through `point` with direction `direction`.

    One equation, `c = n . (r_P - point)` with `n` the unit normal of the line; the body turns
    and slides freely.
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    point: jnp.ndarray
    direction: jnp.ndarray

    def __init__(self, body: int, marker: int, point=(0.0, 0.0), direction=(1.0, 0.0)):
        d = finite_vector(direction, "PointOnLine direction", 2)
        if float(jnp.linalg.norm(d)) == 0.0:
            raise ValueError("PointOnLine direction must be a non-zero (2,) vector, got (0, 0).")
        self.body, self.marker = body, marker
        self.point = finite_vector(point, "PointOnLine point", 2)
        self.direction = d / jnp.linalg.norm(d)

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        del t
        normal = jnp.stack([-self.direction[1], self.direction[0]])
        return jnp.sum(normal * (scene.marker_position(self.body, self.marker, y_r) - self.point))[None]
