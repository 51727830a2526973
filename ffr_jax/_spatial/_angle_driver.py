"""Rheonomic driver of a spatial body's rotation angle about a ground axis."""

import equinox as eqx
import jax.numpy as jnp

from .._scene._base import AbstractConstraint
from .._scene._laws import AbstractLaw, as_law
from ._revolute import unit_axis
from ._spherical import require_spatial


class SpatialAngleDriver(AbstractConstraint):
    """Body `body` is turned by the prescribed angle `phi(t)` about the inertial unit axis `n` (from its
    orientation at `phi = 0`, the identity): Euler parameters `p ~ (cos(phi/2), sin(phi/2) n)`.

    One equation, `c = sin(phi/2) e0 - cos(phi/2) (n . e)`: homogeneous in `p` (the gauge `|p|` stays free) and
    regular at every angle. With a hinge about the same axis ([`SpatialRevolute`][]) it fixes the rotation. It
    leaves the length of `p` free: add [`EulerNormalisation`][] for the body so that no independent coordinate
    is left to the gauge (a fixed partition would otherwise take `e0` or `n . e` as independent, which vanishes
    at some angle of a full turn).

    **Arguments:**
    - `body`: the driven body; `axis`: `(3,)` inertial axis (a `ValueError` for zero length);
    - `angle`: an [`AbstractLaw`][] of time (or a number).
    """

    body: int = eqx.field(static=True)
    axis: jnp.ndarray
    angle: AbstractLaw

    def __init__(self, body: int, axis, angle):
        self.body = int(body)
        self.axis = jnp.asarray(unit_axis(axis, "SpatialAngleDriver axis"))
        self.angle = as_law(angle)

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        require_spatial(scene, (self.body,), "SpatialAngleDriver")
        p = scene.body_coordinates(self.body, y_r)[3:7]
        half = 0.5 * self.angle(t)
        return (jnp.sin(half) * p[0] - jnp.cos(half) * (self.axis @ p[1:]))[None]


class EulerNormalisation(AbstractConstraint):
    """`|p|^2 - 1 = 0` for the Euler parameters of body `body`: one equation that removes the gauge direction.

    Not needed in general (the rotation is `A(p / |p|)` and the equations of motion keep `|p|` constant), and
    harmful for a body that turns freely (one Euler parameter becomes dependent, and every fixed one vanishes
    somewhere on a full turn, where the partition is singular). Useful where the rotation is prescribed
    ([`SpatialAngleDriver`][]): then all four parameters are dependent and regular at every angle.
    """

    body: int = eqx.field(static=True)

    @property
    def n_equations(self) -> int:
        return 1

    def residual(self, t, y_r, scene):
        del t
        require_spatial(scene, (self.body,), "EulerNormalisation")
        p = scene.body_coordinates(self.body, y_r)[3:7]
        return (p @ p - 1.0)[None]
