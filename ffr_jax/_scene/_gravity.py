"""Gravity on every body."""

import jax.numpy as jnp

from .._dynamics._body_dynamics import rotation
from .._spatial import _rigid_body as spatial
from .._spatial._body_data import SpatialBodyData
from .._spatial import _flexible_body as spatial_flexible
from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from ._base import AbstractForce
from ._references import finite_vector


class Gravity(AbstractForce):
    """Uniform gravity `g` `(2,)` on all bodies.

    For a body, the virtual work of `M (e g)` over the mesh gives exactly the `R` columns of the
    body mass matrix times `g`: `Q_R = m g`, `Q_theta = (A I~ S_u) . g`, `Q_q = S1^T A^T g`.
    Potential `V = -g . (m R + A S_u)` with `S_u = s0 + S1 q`. A spatial body (a (3,) `g`) gets
    `Q = -dV/dy_b` of `V = -g . (m R + A(p) s)`.
    """

    acceleration: jnp.ndarray

    def __init__(self, acceleration=(0.0, -9.81)):
        self.acceleration = finite_vector(acceleration, "Gravity acceleration", (2, 3))

    def generalized_force(self, t, y_r, z_r, scene):
        del t, z_r
        parts = []
        for b, body in enumerate(scene.bodies):
            y_b = scene.body_coordinates(b, y_r)
            if isinstance(body.data, SpatialBodyData):
                parts.append(spatial.gravity_force(body.data, self._spatial(), y_b))
                continue
            if isinstance(body.data, SpatialFlexibleBodyData):
                parts.append(spatial_flexible.gravity_force(body.data, self._spatial(), y_b))
                continue
            a = rotation(y_b[2])
            s_u = body.data.first_moment + body.data.modal_moment @ y_b[3:]
            g = self.acceleration
            q_theta = a @ jnp.stack([-s_u[1], s_u[0]])
            parts.append(jnp.concatenate([body.data.mass * g, (q_theta @ g)[None], body.data.modal_moment.T @ (a.T @ g)]))
        return jnp.concatenate(parts)

    def potential_energy(self, t, y_r, scene):
        del t
        total = jnp.zeros(())
        for b, body in enumerate(scene.bodies):
            y_b = scene.body_coordinates(b, y_r)
            if isinstance(body.data, SpatialBodyData):
                total = total + spatial.gravity_potential(body.data, self._spatial(), y_b)
                continue
            if isinstance(body.data, SpatialFlexibleBodyData):
                total = total + spatial_flexible.gravity_potential(body.data, self._spatial(), y_b)
                continue
            s_u = body.data.first_moment + body.data.modal_moment @ y_b[3:]
            total = total - self.acceleration @ (body.data.mass * y_b[:2] + rotation(y_b[2]) @ s_u)
        return total

    def _spatial(self):
        """The acceleration for a spatial body, or a `ValueError` when it is not `(3,)`."""
        if self.acceleration.shape != (3,):
            raise ValueError(f"Gravity on a spatial body needs a (3,) acceleration, e.g. Gravity((0.0, 0.0, -9.81)); "
                             f"got shape {self.acceleration.shape}.")
        return self.acceleration
