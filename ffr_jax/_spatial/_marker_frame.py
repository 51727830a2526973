"""Directions fixed at a joint marker of a spatial body (or of the ground), in inertial coordinates."""

import jax.numpy as jnp
import numpy as np

from . import _flexible_body
from ._euler_parameters import rotation_matrix
from ._flexible_body_data import SpatialFlexibleBodyData


def marker_directions(scene, body: int, marker: int, vectors, y_r):
    """The inertial directions `(k, 3)` of the body-frame directions `vectors` `(k, 3)` at marker `marker` of
    spatial body `body`: `A(p) v` for a rigid body, `A(p) (v + (Psi_P q) x v)` for a flexible one (its elastic
    rotation at the marker, linear as the FFR's small deformations are); `vectors` themselves for the ground
    (`body < 0`: they are inertial)."""
    if body < 0:
        return vectors
    y_b = scene.body_coordinates(body, y_r)
    data = scene.bodies[body].data
    if isinstance(data, SpatialFlexibleBodyData):
        return jnp.stack([_flexible_body.marker_axis(data, marker, y_b, v) for v in vectors])
    return vectors @ rotation_matrix(y_b[3:7]).T


def perpendicular_unit(vector, axis: np.ndarray, name: str) -> np.ndarray:
    """`vector / |vector|` `(3,)`, or a `ValueError` when it is not finite, of zero length, or not perpendicular
    to the unit `axis` (to 1e-8 in the cosine of the angle between them)."""
    v = np.asarray(vector, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0.0:
        raise ValueError(f"{name} must be a finite, non-zero (3,) vector, got {vector!r}.")
    v = v / np.linalg.norm(v)
    if abs(v @ axis) > 1e-8:
        raise ValueError(f"{name} {vector!r} is not perpendicular to its joint axis {axis.tolist()} (cosine "
                         f"{v @ axis:.3g}): give a direction at right angles to the axis.")
    return v
