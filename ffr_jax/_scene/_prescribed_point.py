"""Revolute joint to a point moving on a prescribed circle (a driven crank pin)."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractConstraint
from ._laws import AbstractLaw
from ._laws import _scalar
from ._references import finite_vector


class CrankPin(AbstractConstraint):
    """Marker `marker` of body `body` follows the crank pin `P(t) = centre + radius (cos phi, sin phi)`.

    The crank is rigid and its angle `phi(t)` is prescribed (rheonomic), so its own mass does
    not enter the dynamics (REFERENCE_CASE §3). Two equations, `c = r_P - P(t)`.
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    radius: jnp.ndarray
    centre: jnp.ndarray
    angle: AbstractLaw

    def __init__(self, body: int, marker: int, radius: float, angle: AbstractLaw, centre=(0.0, 0.0)):
        self.body, self.marker = body, marker
        self.radius = _scalar(radius, "CrankPin radius")
        self.centre = finite_vector(centre, "CrankPin centre", 2)
        self.angle = angle

    @property
    def n_equations(self) -> int:
        return 2

    def pin(self, t):
        phi = self.angle(t)
        return self.centre + self.radius * jnp.stack([jnp.cos(phi), jnp.sin(phi)])

    def residual(self, t, y_r, scene):
        return scene.marker_position(self.body, self.marker, y_r) - self.pin(t)
