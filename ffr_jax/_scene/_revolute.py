"""Revolute joint between markers of two bodies."""

import equinox as eqx

from ._base import AbstractConstraint


class Revolute(AbstractConstraint):
    """Marker `marker_i` of body `body_i` coincides with marker `marker_j` of body `body_j`.

    `c = r_i(P) - r_j(Q)`, two equations; rotations are free.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)

    @property
    def n_equations(self) -> int:
        return 2

    def residual(self, t, y_r, scene):
        del t
        return scene.marker_position(self.body_i, self.marker_i, y_r) - scene.marker_position(
            self.body_j, self.marker_j, y_r
        )
