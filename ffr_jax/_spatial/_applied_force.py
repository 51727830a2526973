"""A prescribed force and torque on a marker of a spatial body."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._scene._base import AbstractForce
from .._scene._laws import AbstractLaw, as_law
from ._marker_load import marker_load
from ._spherical import require_spatial


def _vector(value, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be a finite (3,) vector, got {value!r}.")
    return v


class SpatialAppliedForce(AbstractForce):
    """Inertial force `F(t) = phi(t) F0` and torque `tau(t) = phi(t) tau0` acting at marker `marker` of spatial body
    `body`.

    Virtual work `F . delta r_P + tau . delta phi_P` with `delta r_P = delta R + A (delta pi' x u_P + Phi_P delta q)`
    and `delta phi_P = A (delta pi' + Psi_P delta q)` (`delta pi' = 2 H delta p` the body-frame virtual rotation,
    `Psi_P` the elastic rotation at the marker of a flexible body), so the generalized force on the body's
    `(R, p, q)` is

    `Q_R = F`, `Q_p = 2 H^T (u_P~ A^T F + A^T tau)`, `Q_q = Phi_P^T A^T F + Psi_P^T A^T tau`

    (`u_P = c_P + Phi_P q`). Its power is `F . rdot_P + tau . omega` (plus `tau . A Psi_P qdot` on a flexible
    body). A torque moves no point, so for a rigid body the marker matters only for the force. The law `phi` has
    array parameters, so `value_and_grad` of a problem differentiates with respect to it and to `F0`, `tau0`.

    **Arguments:**
    - `body`, `marker`: where the load acts.
    - `force`: `(3,)` inertial force `F0` (default zero); `torque`: `(3,)` inertial torque `tau0` (default zero).
    - `magnitude`: `phi(t)`, an [`AbstractLaw`][] of time or a number (default 1: a constant load).

    Raises `ValueError` for a vector that is not finite `(3,)`, or when both are zero.
    """

    body: int = eqx.field(static=True)
    marker: int = eqx.field(static=True)
    force: jnp.ndarray
    torque: jnp.ndarray
    magnitude: AbstractLaw

    def __init__(self, body: int, marker: int, force=(0.0, 0.0, 0.0), torque=(0.0, 0.0, 0.0), magnitude=1.0):
        f = _vector(force, "SpatialAppliedForce force")
        tau = _vector(torque, "SpatialAppliedForce torque")
        if not (np.any(f != 0.0) or np.any(tau != 0.0)):
            raise ValueError("SpatialAppliedForce needs a non-zero force or torque (both are zero).")
        self.body, self.marker = int(body), int(marker)
        self.force, self.torque = jnp.asarray(f), jnp.asarray(tau)
        self.magnitude = as_law(magnitude)

    def loads(self, t):
        """`(F(t), tau(t))`, each `(3,)`."""
        phi = self.magnitude(t)
        return phi * self.force, phi * self.torque

    def generalized_force(self, t, y_r, z_r, scene):
        del z_r
        require_spatial(scene, (self.body,), "SpatialAppliedForce")
        force, torque = self.loads(t)
        data = scene.bodies[self.body].data
        return scene.scatter(self.body, marker_load(data, self.marker, scene.body_coordinates(self.body, y_r),
                                                    force, torque))
