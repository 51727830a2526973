"""Revolute joint with an axis between two spatial bodies, or between a body and the ground."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._scene._base import AbstractConstraint
from . import _flexible_body
from ._euler_parameters import rotation_matrix
from ._flexible_body_data import SpatialFlexibleBodyData
from ._spherical import ground_point, other_point, require_spatial


def unit_axis(axis, name: str) -> np.ndarray:
    """`axis / |axis|` `(3,)`, or a `ValueError` for an axis of zero length or of another shape."""
    a = np.asarray(axis, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (3,) vector, got {axis!r}.")
    norm = np.linalg.norm(a)
    if not norm > 1e-12 * max(np.max(np.abs(a)), 1.0) or norm == 0.0:
        raise ValueError(f"{name} has zero length ({axis!r}): a joint axis needs a direction. Give a non-zero vector "
                         "in the body's (or, for the ground, the inertial) frame.")
    return a / norm


def normals(axis: np.ndarray) -> np.ndarray:
    """Two unit vectors `(2, 3)` orthogonal to the unit `axis` and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    b1 = np.cross(axis, helper)
    b1 /= np.linalg.norm(b1)
    return np.stack([b1, np.cross(axis, b1)])


def marker_axis(scene, body: int, marker: int, axis_body, y_r):
    """The inertial direction of the body-frame direction `axis_body` at marker `marker` of spatial body `body`:
    `A(p) a` for a rigid body, `A(p) (a + (Psi_P q) x a)` for a flexible one (its elastic rotation at the marker)."""
    y_b = scene.body_coordinates(body, y_r)
    data = scene.bodies[body].data
    if isinstance(data, SpatialFlexibleBodyData):
        return _flexible_body.marker_axis(data, marker, y_b, axis_body)
    return rotation_matrix(y_b[3:7]) @ axis_body


class AbstractAxisJoint(AbstractConstraint):
    """A joint between marker `marker_i` and axis `axis_i` of body `body_i` and marker `marker_j` and axis `axis_j`
    of body `body_j` (or, with `body_j = -1`, the inertial `point` and `axis_j`): the fields and constructor that
    [`SpatialRevolute`][ffr_jax.SpatialRevolute] and [`SpatialCylindrical`][ffr_jax.SpatialCylindrical] share.
    `axis_j` defaults to `axis_i`; the axes are normalised, and `axis_j` is kept as its two unit normals
    `normals_j`. Raises `ValueError` for an axis of zero length and a ground point that is not a finite `(3,)`
    vector."""

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    axis_i: jnp.ndarray
    normals_j: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, axis_i, body_j: int = -1, marker_j: int = 0, axis_j=None,
                 point=(0.0, 0.0, 0.0)):
        name = type(self).__name__
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        a_i = unit_axis(axis_i, f"{name} axis_i")
        a_j = a_i if axis_j is None else unit_axis(axis_j, f"{name} axis_j")
        self.axis_i = jnp.asarray(a_i)
        self.normals_j = jnp.asarray(normals(a_j))
        self.point = ground_point(point, name)


class SpatialRevolute(AbstractAxisJoint):
    """A hinge: marker `marker_i` of body `body_i` on marker `marker_j` of body `body_j`, and the body axis
    `axis_i` of body `i` parallel to the axis `axis_j` of body `j`.

    Five equations: `r_i(P) - r_j(Q) = 0` and `b_k . (A_i a_i) = 0` for the two normals `b_1, b_2` of
    `A_j a_j` (at a flexible body's marker the axis turns with the elastic rotation `Psi q` there).
    `body_j = -1` (the default) makes `point` and `axis_j` inertial (a hinge to the ground).

    **Arguments:**
    - `body_i`, `marker_i`, `axis_i`: the first body, its joint marker and hinge axis (body frame).
    - `body_j`, `marker_j`, `axis_j`: the second body (or `-1`: the ground), its marker and axis.
    - `point`: `(3,)` ground point when `body_j = -1`.

    Raises `ValueError` for an axis of zero length.
    """

    @property
    def n_equations(self) -> int:
        return 5

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialRevolute")
        position = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a_i = marker_axis(scene, self.body_i, self.marker_i, self.axis_i, y_r)
        if self.body_j < 0:
            b = self.normals_j
        elif isinstance(scene.bodies[self.body_j].data, SpatialFlexibleBodyData):
            b = jnp.stack([marker_axis(scene, self.body_j, self.marker_j, n, y_r) for n in self.normals_j])
        else:
            b = self.normals_j @ rotation_matrix(scene.body_coordinates(self.body_j, y_r)[3:7]).T
        return jnp.concatenate([position, b @ a_i])
