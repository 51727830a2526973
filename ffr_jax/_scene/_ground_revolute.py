"""Revolute joint between a body marker and a fixed point of the ground."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractConstraint
from ._references import finite_vector


class GroundRevolute(AbstractConstraint):
    """Marker `marker` of body `body` stays at the inertial point `point`: `c = r_P - point`."""

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    point: jnp.ndarray

    def __init__(self, body: int, marker: int, point=(0.0, 0.0)):
        self.body, self.marker = body, marker
        self.point = finite_vector(point, "GroundRevolute point", 2)

    @property
    def n_equations(self) -> int:
        return 2

    def residual(self, t, y_r, scene):
        del t
        return scene.marker_position(self.body, self.marker, y_r) - self.point
