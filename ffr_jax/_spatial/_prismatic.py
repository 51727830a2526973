"""Prismatic (translational) joint between two spatial bodies, or between a body and the ground."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._scene._base import AbstractConstraint
from ._marker_frame import marker_directions, perpendicular_unit
from ._revolute import normals, unit_axis
from ._spherical import ground_point, other_point, require_spatial


class SpatialPrismatic(AbstractConstraint):
    """Marker `marker_i` of body `body_i` slides along the axis through marker `marker_j` of body `body_j`, without
    turning relative to it: one relative motion is free, the translation along the axis.

    Five equations: those of [`SpatialCylindrical`][] and one that stops the rotation about the axis. With
    `a_i = A_i a_i'`, `n_i = A_i n_i'` (a direction of body `i` at right angles to its axis), `n_j = A_j n_j'`,
    `m_j = A_j (a_j' x n_j')` and `d = r_i(P) - r_j(Q)`:

    `c = [n_j . a_i, m_j . a_i, n_i . m_j, n_j . d, m_j . d]`.

    The third equation holds where `n_i` is parallel to `n_j` (`+-`: the assembly picks the branch, as for any
    joint). At the marker of a flexible body the directions turn with its elastic rotation `Psi_P q` there.
    `body_j = -1` (the default) makes `point`, `axis_j` and `normal_j` inertial.

    **Arguments:**
    - `body_i`, `marker_i`, `axis_i`: the sliding body, its marker and sliding axis `(3,)` (body frame).
    - `body_j`, `marker_j`, `axis_j`: the guide (or `-1`: the ground), its marker and axis (default: `axis_i`).
    - `normal_i`, `normal_j`: `(3,)` directions at right angles to `axis_i`, `axis_j` that stay parallel (required
      when the axes differ; for one axis, either one given serves for both, and by default one normal of the axis
      does: the bodies keep the relative orientation in which their frames are parallel).
    - `point`: `(3,)` a point of the ground axis when `body_j = -1`.

    Raises `ValueError` for an axis of zero length, a normal that is not perpendicular to its axis, or different
    axes without the normals that fix the relative rotation about them.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    axis_i: jnp.ndarray
    normal_i: jnp.ndarray
    normals_j: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, axis_i, body_j: int = -1, marker_j: int = 0, axis_j=None,
                 normal_i=None, normal_j=None, point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        a_i = unit_axis(axis_i, "SpatialPrismatic axis_i")
        a_j = a_i if axis_j is None else unit_axis(axis_j, "SpatialPrismatic axis_j")
        same_axis = axis_j is None or np.allclose(a_i, a_j, rtol=0.0, atol=1e-14)
        if not same_axis and (normal_i is None or normal_j is None):
            raise ValueError("SpatialPrismatic with axis_i != axis_j needs normal_i and normal_j: a direction at right "
                             "angles to each axis, the two parallel in the assembled configuration (they fix the "
                             "relative rotation about the axis).")
        n_i = n_j = normals(a_i)[0]
        if normal_i is not None:
            n_i = n_j = perpendicular_unit(normal_i, a_i, "SpatialPrismatic normal_i")
        if normal_j is not None:
            n_j = perpendicular_unit(normal_j, a_j, "SpatialPrismatic normal_j")
            n_i = n_j if normal_i is None else n_i
        self.axis_i = jnp.asarray(a_i)
        self.normal_i = jnp.asarray(n_i)
        self.normals_j = jnp.asarray(np.stack([n_j, np.cross(a_j, n_j)]))
        self.point = ground_point(point, "SpatialPrismatic")

    @property
    def n_equations(self) -> int:
        return 5

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialPrismatic")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a_i, n_i = marker_directions(scene, self.body_i, self.marker_i, jnp.stack([self.axis_i, self.normal_i]), y_r)
        b = marker_directions(scene, self.body_j, self.marker_j, self.normals_j, y_r)
        return jnp.concatenate([b @ a_i, (n_i @ b[1])[None], b @ d])
