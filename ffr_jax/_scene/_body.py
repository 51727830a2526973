"""A body of a scene: a name and its standard input data."""

import equinox as eqx

from ._body_data import BodyData


class Body(eqx.Module):
    """A planar body with coordinates `(R_x, R_y, theta, q_1..q_{n_q})`; rigid when `n_q = 0`."""

    name: str = eqx.field(static=True)
    data: BodyData

    @property
    def n_coordinates(self) -> int:
        return 3 + self.data.n_modes
