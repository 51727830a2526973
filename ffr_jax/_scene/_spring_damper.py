"""Linear spring–damper between two points."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import AbstractForce
from ._laws import _scalar
from ._references import finite_vector


class SpringDamper(AbstractForce):
    """Spring–damper from marker `marker_i` of body `body_i` to a marker of `body_j` or a ground point.

    Force magnitude `k (l - l0) + d l'` along the line of the two points. Its generalized force
    is `-dV/dy_r - dD/dz_r` with `V = 1/2 k (l - l0)^2` and `D = 1/2 d l'^2`, obtained with JAX.
    `body_j = -1` attaches the other end to the inertial point `ground_point`.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    stiffness: jnp.ndarray
    damping: jnp.ndarray
    rest_length: jnp.ndarray
    ground_point: jnp.ndarray

    def __init__(self, body_i, marker_i, body_j=-1, marker_j=0, *, stiffness, damping=0.0, rest_length=0.0,
                 ground_point=(0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = body_i, marker_i, body_j, marker_j
        self.stiffness = _scalar(stiffness, "SpringDamper stiffness")
        self.damping = _scalar(damping, "SpringDamper damping")
        self.rest_length = _scalar(rest_length, "SpringDamper rest_length")
        self.ground_point = finite_vector(ground_point, "SpringDamper ground_point", (2, 3))

    def _length(self, y_r, scene):
        a = scene.marker_position(self.body_i, self.marker_i, y_r)
        if self.body_j < 0:
            b = self.ground_point
        else:
            b = scene.marker_position(self.body_j, self.marker_j, y_r)
        return jnp.sqrt(jnp.sum((a - b) ** 2))

    def potential_energy(self, t, y_r, scene):
        del t
        return 0.5 * self.stiffness * (self._length(y_r, scene) - self.rest_length) ** 2

    def generalized_force(self, t, y_r, z_r, scene):
        length, rate = jax.jvp(lambda y: self._length(y, scene), (y_r,), (z_r,))
        force = self.stiffness * (length - self.rest_length) + self.damping * rate
        return -force * jax.grad(lambda y: self._length(y, scene))(y_r)
