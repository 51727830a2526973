"""Linear spring–damper between markers of two spatial bodies, or a marker and a ground point."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractForce
from .._scene._laws import _scalar
from ._marker_load import marker_load, marker_velocity
from ._spherical import ground_point, other_point, require_spatial


class SpatialSpringDamper(AbstractForce):
    """Spring–damper from marker `marker_i` of spatial body `body_i` to marker `marker_j` of body `body_j`, or to
    the inertial point `point` (`body_j = -1`, the default).

    With `d = r_i(P) - r_j(Q)`, length `l = |d|`, unit `e = d / l` and rate `l' = e . (rdot_i(P) - rdot_j(Q))`, the
    force `f = k (l - l0) + c l'` pulls the ends together: `-f e` acts at `P`, `+f e` at `Q`. Its virtual work is
    `delta W = -f delta l = -f e . (delta r_i(P) - delta r_j(Q))`, so the generalized force is that of the two end
    forces on each body's `(R, p, q)` (`_marker_load`: `Q_R = F`, `Q_p = 2 H^T u_P~ A^T F`, `Q_q = Phi_P^T A^T F`),
    equal to `-dV/dy_r - dD/dz_r` with the potential `V = 1/2 k (l - l0)^2` and the dissipation function
    `D = 1/2 c l'^2`; the damper dissipates the power `c l'^2`. The ends must not meet (`l > 0`).

    **Arguments:**
    - `body_i`, `marker_i`: the first end; `body_j`, `marker_j`: the second end's body (or `-1`) and marker.
    - `stiffness` `k`, `damping` `c`, `rest_length` `l0`: numbers (arrays inside: differentiable).
    - `point`: `(3,)` the ground end when `body_j = -1`.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    stiffness: jnp.ndarray
    damping: jnp.ndarray
    rest_length: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, body_j: int = -1, marker_j: int = 0, *, stiffness, damping=0.0,
                 rest_length=0.0, point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        self.stiffness = _scalar(stiffness, "SpatialSpringDamper stiffness")
        self.damping = _scalar(damping, "SpatialSpringDamper damping")
        self.rest_length = _scalar(rest_length, "SpatialSpringDamper rest_length")
        self.point = ground_point(point, "SpatialSpringDamper")

    def length(self, t, y_r, scene):
        """`l = |r_i(P) - r_j(Q)|`."""
        require_spatial(scene, (self.body_i, self.body_j), "SpatialSpringDamper")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        return jnp.sqrt(d @ d)

    def potential_energy(self, t, y_r, scene):
        return 0.5 * self.stiffness * (self.length(t, y_r, scene) - self.rest_length) ** 2

    def length_rate(self, t, y_r, z_r, scene):
        """`l' = e . (rdot_i(P) - rdot_j(Q))`."""
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        v = self._velocity(self.body_i, self.marker_i, y_r, z_r, scene)
        if self.body_j >= 0:
            v = v - self._velocity(self.body_j, self.marker_j, y_r, z_r, scene)
        return d @ v / jnp.sqrt(d @ d)

    def generalized_force(self, t, y_r, z_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialSpringDamper")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        length = jnp.sqrt(d @ d)
        e = d / length
        force = self.stiffness * (length - self.rest_length) + self.damping * self.length_rate(t, y_r, z_r, scene)
        zero = jnp.zeros(3, y_r.dtype)
        q = scene.scatter(self.body_i, marker_load(scene.bodies[self.body_i].data, self.marker_i,
                                                   scene.body_coordinates(self.body_i, y_r), -force * e, zero))
        if self.body_j >= 0:
            q = q + scene.scatter(self.body_j, marker_load(scene.bodies[self.body_j].data, self.marker_j,
                                                           scene.body_coordinates(self.body_j, y_r), force * e, zero))
        return q

    @staticmethod
    def _velocity(body, marker, y_r, z_r, scene):
        return marker_velocity(scene.bodies[body].data, marker, scene.body_coordinates(body, y_r),
                               scene.body_coordinates(body, z_r))
