"""A body of a scene: a name and its standard input data."""

import equinox as eqx

from .._spatial._body_data import SpatialBodyData
from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from ._body_data import BodyData


class Body(eqx.Module):
    """A body with coordinates `(R_x, R_y, theta, q_1..q_{n_q})` (planar [`BodyData`][]; rigid when `n_q = 0`)
    or `(R_x, R_y, R_z, e0, e1, e2, e3)` (a rigid spatial body, [`SpatialBodyData`][]; Euler parameters),
    followed by `q_1..q_{n_q}` for a flexible spatial body ([`SpatialFlexibleBodyData`][])."""

    name: str = eqx.field(static=True)
    data: BodyData | SpatialBodyData | SpatialFlexibleBodyData

    @property
    def n_coordinates(self) -> int:
        if isinstance(self.data, SpatialBodyData):
            return 7
        if isinstance(self.data, SpatialFlexibleBodyData):
            return 7 + self.data.n_modes
        return 3 + self.data.n_modes
