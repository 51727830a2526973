"""Cylindrical joint between two spatial bodies, or between a body and the ground."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from ._marker_frame import marker_directions
from ._revolute import normals, unit_axis
from ._spherical import ground_point, other_point, require_spatial


class SpatialCylindrical(AbstractConstraint):
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

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    axis_i: jnp.ndarray
    normals_j: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, axis_i, body_j: int = -1, marker_j: int = 0, axis_j=None,
                 point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        a_i = unit_axis(axis_i, "SpatialCylindrical axis_i")
        a_j = a_i if axis_j is None else unit_axis(axis_j, "SpatialCylindrical axis_j")
        self.axis_i = jnp.asarray(a_i)
        self.normals_j = jnp.asarray(normals(a_j))
        self.point = ground_point(point, "SpatialCylindrical")

    @property
    def n_equations(self) -> int:
        return 4

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialCylindrical")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a_i = marker_directions(scene, self.body_i, self.marker_i, self.axis_i[None], y_r)[0]
        b = marker_directions(scene, self.body_j, self.marker_j, self.normals_j, y_r)
        return jnp.concatenate([b @ a_i, b @ d])
