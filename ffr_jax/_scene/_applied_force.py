"""A prescribed force on a body marker."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import AbstractForce
from ._laws import AbstractLaw, as_law


class AppliedForce(AbstractForce):
    """Inertial force `f(t) = magnitude(t) d` `(2,)` acting at marker `marker` of body `body`.

    Generalized force `Q = (dr_P/dy_r)^T f(t)`, one vector–Jacobian product. The magnitude is a law
    of time with array parameters ([`ConstantLaw`][], [`HarmonicLaw`][], [`RampLaw`][], ...), so
    `value_and_grad` of a problem differentiates with respect to it.

    **Arguments:**
    - `body`, `marker`: where the force acts.
    - `magnitude`: a number (constant force) or an [`AbstractLaw`][] of time.
    - `direction`: `(2,)` inertial direction (normalised here).
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    magnitude: AbstractLaw
    direction: jnp.ndarray

    def __init__(self, body: int, marker: int, magnitude, direction=(1.0, 0.0)):
        d = jnp.asarray(direction, dtype=float)
        if d.shape != (2,) or not bool(jnp.all(jnp.isfinite(d))) or float(jnp.linalg.norm(d)) == 0.0:
            raise ValueError(f"AppliedForce direction must be a finite, non-zero (2,) vector, got {direction!r}.")
        self.body, self.marker = int(body), int(marker)
        self.magnitude = as_law(magnitude)
        self.direction = d / jnp.linalg.norm(d)

    def force(self, t):
        """`f(t)`, shape `(2,)`."""
        return self.magnitude(t) * self.direction

    def generalized_force(self, t, y_r, z_r, scene):
        del z_r
        _, pullback = jax.vjp(lambda y: scene.marker_position(self.body, self.marker, y), y_r)
        return pullback(self.force(t))[0]
