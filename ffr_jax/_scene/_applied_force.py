"""A prescribed force on a body marker."""

from collections.abc import Callable

import equinox as eqx
import jax

from ._base import AbstractForce


class AppliedForce(AbstractForce):
    """Inertial force `f(t)` `(2,)` acting at marker `marker` of body `body`.

    Generalized force `Q = (dr_P/dy_r)^T f(t)`, one vector–Jacobian product.
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    force: Callable = eqx.field(static=True)

    def generalized_force(self, t, y_r, z_r, scene):
        del z_r
        _, pullback = jax.vjp(lambda y: scene.marker_position(self.body, self.marker, y), y_r)
        return pullback(self.force(t))[0]
