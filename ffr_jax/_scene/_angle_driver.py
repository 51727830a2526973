"""Rheonomic driver of a body's rotation angle."""

import equinox as eqx

from ._base import AbstractConstraint
from ._laws import AbstractLaw


class AngleDriver(AbstractConstraint):
    """Body `body` turns as prescribed: `c = theta - phi(t)`, one equation."""

    body: int = eqx.field(static=True)
    angle: AbstractLaw

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        return (scene.body_coordinates(self.body, y_r)[2] - self.angle(t))[None]
