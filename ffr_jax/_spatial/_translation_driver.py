"""Rheonomic driver of the relative displacement of two spatial bodies (or a body and the ground) along an axis."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from .._scene._laws import AbstractLaw, as_law
from ._marker_frame import marker_directions
from ._revolute import unit_axis
from ._spherical import ground_point, other_point, require_spatial


class SpatialTranslationDriver(AbstractConstraint):
    """Marker `marker_i` of body `body_i` is moved by the prescribed displacement `s(t)` along the axis `a_j` of
    body `body_j` (or of the ground), measured from marker `marker_j` (or from `point`).

    One equation, `c = (A_j a_j') . (r_i(P) - r_j(Q)) - s(t)` (at the marker of a flexible body `j` the axis turns
    with its elastic rotation `Psi_Q q` there). With a [`SpatialPrismatic`][] or [`SpatialCylindrical`][] joint
    about the same axis it fixes the slide (a linear actuator); its multiplier is the actuator's force.

    **Arguments:**
    - `body_i`, `marker_i`: the driven body and its marker.
    - `axis`: `(3,)` the direction of the displacement in body `j`'s frame (inertial for the ground).
    - `displacement`: an [`AbstractLaw`][] of time (or a number), `s(t)`.
    - `body_j`, `marker_j`: the reference body (default `-1`: the ground) and its marker.
    - `point`: `(3,)` the origin of the displacement when `body_j = -1`.

    Raises `ValueError` for an axis of zero length; a planar body is refused when the scene is traced.
    """

    body_i: int = eqx.field(static=True)
    marker_i: int = eqx.field(static=True)
    body_j: int = eqx.field(static=True)
    marker_j: int = eqx.field(static=True)
    axis: jnp.ndarray
    displacement: AbstractLaw
    point: jnp.ndarray

    def __init__(self, body_i: int, marker_i: int, axis, displacement, body_j: int = -1, marker_j: int = 0,
                 point=(0.0, 0.0, 0.0)):
        self.body_i, self.marker_i, self.body_j, self.marker_j = int(body_i), int(marker_i), int(body_j), int(marker_j)
        self.axis = jnp.asarray(unit_axis(axis, "SpatialTranslationDriver axis"))
        self.displacement = as_law(displacement)
        self.point = ground_point(point, "SpatialTranslationDriver")

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body_i, self.body_j), "SpatialTranslationDriver")
        d = scene.marker_position(self.body_i, self.marker_i, y_r) - other_point(self, t, y_r, scene)
        a = marker_directions(scene, self.body_j, self.marker_j, self.axis[None], y_r)[0]
        return (a @ d - self.displacement(t))[None]
