"""Rigid attachment (a weld, a fixed joint) of two spatial bodies, or of a body to the ground."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._scene._base import AbstractConstraint
from ._euler_parameters import rotation_matrix
from ._marker_frame import marker_directions
from ._spherical import ground_point, other_point, require_spatial


def relative_rotation(rotation, name: str) -> np.ndarray:
    """A rotation matrix `(3, 3)` from a matrix or Euler parameters `(4,)`, or a `ValueError`."""
    r = np.asarray(rotation, dtype=float)
    if r.shape == (4,) and np.all(np.isfinite(r)) and np.linalg.norm(r) > 0.0:
        return np.asarray(rotation_matrix(jnp.asarray(r)))
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError(f"{name} must be a (3, 3) rotation matrix or (4,) non-zero Euler parameters, "
                         f"got {rotation!r}.")
    if np.max(np.abs(r.T @ r - np.eye(3))) > 1e-10 or np.linalg.det(r) < 0.0:
        raise ValueError(f"{name} is not a rotation matrix (R^T R = I to 1e-10 and det R = +1): {r.tolist()}. "
                         "Give an orthonormal matrix without reflection, or Euler parameters "
                         "(ffr_jax.euler_parameters).")
    return r


class SpatialRigidAttachment(AbstractConstraint):
    """Body `body_i` is welded to body `body_j` at their markers: no relative motion at all.

    Six equations. With `C` the orientation of body `i`'s marker frame in body `j`'s (`A_i = A_j C` when attached),
    `u_k = A_i e_k` and `v_k = A_j C e_k`:

    `c = [r_i(P) - r_j(Q), u_1 . v_2, u_1 . v_3, u_2 . v_3]`.

    The three products vanish where the frames `u` and `v` coincide (their Jacobian there has full rank: a small
    relative rotation `delta phi` changes them by `delta phi . (u_3, -u_2, u_1)`); the assembly picks this branch
    from a configuration near it. At the marker of a flexible body the frame turns with its elastic rotation
    `Psi_P q` there. `body_j = -1` (the default) attaches body `i` to the ground: its marker at `point`, its frame
    at `A_i = C`.

    **Arguments:**
    - `body_i`, `marker_i`: the attached body and its marker.
    - `body_j`, `marker_j`: the carrier (or `-1`: the ground) and its marker.
    - `rotation`: `C`, a `(3, 3)` rotation matrix or `(4,)` Euler parameters (default: the identity, the frames
      parallel).
    - `point`: `(3,)` ground point when `body_j = -1`.

    Raises `ValueError` for a `rotation` that is not a rotation; a planar body is refused when the scene is traced.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    frame_j: jnp.ndarray
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, body_j: int = -1, marker_j: int = 0, rotation=None,
                 point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        c = np.eye(3) if rotation is None else relative_rotation(rotation, "SpatialRigidAttachment rotation")
        self.frame_j = jnp.asarray(c.T)  # rows: C e_1, C e_2, C e_3 in body j's frame
        self.point = ground_point(point, "SpatialRigidAttachment")

    @property
    def n_equations(self) -> int:
        return 6

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialRigidAttachment")
        position = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        u = marker_directions(scene, self.body_i, self.marker_i, jnp.eye(3, dtype=y_r.dtype), y_r)
        v = marker_directions(scene, self.body_j, self.marker_j, self.frame_j, y_r)
        return jnp.concatenate([position, jnp.stack([u[0] @ v[1], u[0] @ v[2], u[1] @ v[2]])])
