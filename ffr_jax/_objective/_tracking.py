"""Tracking of a marker point's position along a target path."""

import abc
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractIntegrand


class AbstractPath(eqx.Module):
    """A target point as a function of time, `r*(t)`, shape `(2,)`."""

    @abc.abstractmethod
    def __call__(self, t):
        """`r*(t)`, shape `(2,)`."""


class FixedPoint(AbstractPath):
    """`r*(t) = point` (an array: differentiable)."""

    point: jnp.ndarray

    def __init__(self, point):
        point = jnp.asarray(point, dtype=float)
        if point.shape != (2,):
            raise ValueError(f"A target point must have shape (2,), got {point.shape}.")
        self.point = point

    def __call__(self, t):
        del t
        return self.point


class LinearPath(AbstractPath):
    """`r*(t) = start + velocity t` (arrays: differentiable)."""

    start: jnp.ndarray
    velocity: jnp.ndarray

    def __init__(self, start, velocity):
        self.start, self.velocity = (jnp.asarray(v, dtype=float) for v in (start, velocity))
        if self.start.shape != (2,) or self.velocity.shape != (2,):
            raise ValueError("LinearPath needs start and velocity of shape (2,).")

    def __call__(self, t):
        return self.start + self.velocity * t


class FunctionPath(AbstractPath):
    """A user function `fn(t) -> (2,)` (static: its constants are not differentiated)."""

    fn: Callable = eqx.field(static=True)

    def __call__(self, t):
        return jnp.asarray(self.fn(t))


def as_path(target) -> AbstractPath:
    """A target given as an [`AbstractPath`][], a function of time, or a fixed `(2,)` point."""
    if isinstance(target, AbstractPath):
        return target
    if callable(target):
        return FunctionPath(target)
    return FixedPoint(target)


class MarkerTracking(AbstractIntegrand):
    """`F = |r_P(y_r) - r*(t)|^2`: squared distance of marker `marker` of body `body` from a target.

    `r_P = R + A(theta) (c_P + Phi_P q)` is the marker's inertial position (elastic displacement
    included). As an integrand, the squared tracking error integrated over the motion; as a
    terminal term, the squared miss distance at `t1`.

    **Arguments:**
    - `body`, `marker`: the tracked point (marker indices as in the body data).
    - `target`: an [`AbstractPath`][] (e.g. [`LinearPath`][], whose arrays can be differentiated),
      a function `t -> (2,)`, or a fixed point `(2,)`.
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    target: AbstractPath

    def __init__(self, body: int, marker: int, target):
        self.body, self.marker = int(body), int(marker)
        self.target = as_path(target)

    def __call__(self, t, y_r, z_r, scene):
        del z_r
        error = scene.marker_position(self.body, self.marker, y_r) - self.target(t)
        return jnp.sum(error**2)
