"""Cylindrical joint between two spatial bodies, or between a body and the ground."""

import jax.numpy as jnp

from ._marker_frame import marker_directions
from ._revolute import AbstractAxisJoint
from ._spherical import other_point, require_spatial


class SpatialCylindrical(AbstractAxisJoint):
    """Marker `marker_i` of body `body_i` slides along, and turns about, the axis through marker `marker_j` of body
    `body_j` (a piston in its cylinder): two relative motions are free, the rotation about and the translation
    along the common axis.

    Four equations, with `a_i = A_i a_i'` the axis of body `i`, `b_1, b_2 = A_j [n_1', n_2']` the two unit normals of
    the axis `a_j'` of body `j` and `d = r_i(P) - r_j(Q)`:

    `c = [b_1 . a_i, b_2 . a_i, b_1 . d, b_2 . d]`

    (the axes parallel, and the point `P` on the line through `Q` along `a_j`). At the marker of a flexible body
    the directions turn with its elastic rotation `Psi_P q` there, as in [`SpatialRevolute`][]. `body_j = -1`
    (the default) makes `point` and `axis_j` inertial (a cylindrical joint to the ground).

    **Arguments:**
    - `body_i`, `marker_i`, `axis_i`: the first body, its joint marker and axis `(3,)` (body frame).
    - `body_j`, `marker_j`, `axis_j`: the second body (or `-1`: the ground), its marker and axis (default:
      `axis_i`).
    - `point`: `(3,)` a point of the ground axis when `body_j = -1`.

    Raises `ValueError` for an axis of zero length; a planar body is refused when the scene is traced.
    """

    @property
    def n_equations(self) -> int:
        return 4

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialCylindrical")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a_i = marker_directions(scene, self.body_i, self.marker_i, self.axis_i[None], y_r)[0]
        b = marker_directions(scene, self.body_j, self.marker_j, self.normals_j, y_r)
        return jnp.concatenate([b @ a_i, b @ d])
