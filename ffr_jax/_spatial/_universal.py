"""Universal (Cardan, Hooke) joint between two spatial bodies, or between a body and the ground."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from ._marker_frame import marker_directions
from ._revolute import unit_axis
from ._spherical import ground_point, other_point, require_spatial


class SpatialUniversal(AbstractConstraint):
    """A Cardan (Hooke) joint: marker `marker_i` of body `body_i` on marker `marker_j` of body `body_j`, and the
    axis `axis_i` of body `i` at right angles to the axis `axis_j` of body `j` (the two arms of the cross, each
    turning in its body's yoke): two relative rotations are free, about each arm.

    Four equations, `c = [r_i(P) - r_j(Q), (A_i a_i') . (A_j a_j')]` (at the marker of a flexible body the arm
    turns with its elastic rotation `Psi_P q` there). A shaft driven through the joint at the bend angle `beta`
    between the shafts turns by `phi_2` with `tan phi_2 = cos(beta) tan phi_1` (angles from the position where the
    input arm is at right angles to the plane of the shafts); the joint is singular at `beta = 90 deg`.
    `body_j = -1` (the default) makes `point` and `axis_j` inertial.

    The arms are given in the bodies' own frames, so whether they are at right angles depends on the configuration:
    the assembly ([`Problem`][]) turns the dependent coordinates until they are.

    **Arguments:**
    - `body_i`, `marker_i`, `axis_i`: the first body, its joint marker and arm `(3,)` (body frame).
    - `body_j`, `marker_j`, `axis_j`: the second body (or `-1`: the ground), its marker and arm (required).
    - `point`: `(3,)` ground point when `body_j = -1`.

    Raises `ValueError` for an arm of zero length or a missing `axis_j`; a planar body is refused when the scene is
    traced.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    axis_i: jnp.ndarray
    axis_j: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, axis_i, body_j: int = -1, marker_j: int = 0,
                 axis_j=None, point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        if axis_j is None:
            raise ValueError("SpatialUniversal needs axis_j, the second arm of the cross in body_j's frame (inertial "
                             "for the ground), at right angles to axis_i in the assembled configuration.")
        self.axis_i = jnp.asarray(unit_axis(axis_i, "SpatialUniversal axis_i"))
        self.axis_j = jnp.asarray(unit_axis(axis_j, "SpatialUniversal axis_j"))
        self.point = ground_point(point, "SpatialUniversal")

    @property
    def n_equations(self) -> int:
        return 4

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialUniversal")
        position = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a_i = marker_directions(scene, self.body_i, self.marker_i, self.axis_i[None], y_r)[0]
        a_j = marker_directions(scene, self.body_j, self.marker_j, self.axis_j[None], y_r)[0]
        return jnp.concatenate([position, (a_i @ a_j)[None]])
