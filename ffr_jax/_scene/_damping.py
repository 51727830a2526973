"""Structural damping of a flexible body."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractForce
from ._laws import _scalar


def _modal_velocities(scene, body: int, z_r):
    """`(q', n_rigid)`: the modal velocities of `body` (they come last in a planar and a spatial body's
    coordinates) and the number of its rigid-body coordinates before them (3 planar, 7 spatial)."""
    z_b = scene.body_coordinates(body, z_r)
    n_rigid = z_b.shape[0] - scene.bodies[body].data.n_modes
    return z_b[n_rigid:], n_rigid


class RayleighDamping(AbstractForce):
    """Rayleigh damping of the elastic coordinates of body `body`: `Q_q = -(alpha M_qq + beta K_qq) q'`."""

    body: int = eqx.field(static=True)
    alpha: jnp.ndarray
    beta: jnp.ndarray

    def __init__(self, body: int, alpha: float = 0.0, beta: float = 0.0):
        self.body = body
        self.alpha, self.beta = _scalar(alpha, "RayleighDamping alpha"), _scalar(beta, "RayleighDamping beta")

    def generalized_force(self, t, y_r, z_r, scene):
        del t, y_r
        data = scene.bodies[self.body].data
        dq, n_rigid = _modal_velocities(scene, self.body, z_r)
        q_force = -(self.alpha * data.modal_mass + self.beta * data.modal_stiffness) @ dq
        return scene.scatter(self.body, jnp.concatenate([jnp.zeros(n_rigid), q_force]))


class ModalDamping(AbstractForce):
    """Modal damping ratio `zeta` for every retained mode of body `body`.

    `Q_q = -2 zeta M_qq Omega q'` with `Omega = sqrt(M_qq^-1 K_qq)` (matrix square root, so the
    force is invariant under rotations of the modal basis).
    """

    body: int = eqx.field(static=True)
    ratio: jnp.ndarray

    def __init__(self, body: int, ratio: float):
        self.body = body
        self.ratio = _scalar(ratio, "ModalDamping ratio")

    def generalized_force(self, t, y_r, z_r, scene):
        del t, y_r
        data = scene.bodies[self.body].data
        dq, n_rigid = _modal_velocities(scene, self.body, z_r)
        chol = jnp.linalg.cholesky(data.modal_mass)
        linv_k = jnp.linalg.solve(chol, jnp.linalg.solve(chol, data.modal_stiffness).T)
        lam, v = jnp.linalg.eigh(0.5 * (linv_k + linv_k.T))
        omega_hat = (v * jnp.sqrt(jnp.maximum(lam, 0.0))) @ v.T
        c = 2 * self.ratio * chol @ omega_hat @ chol.T
        return scene.scatter(self.body, jnp.concatenate([jnp.zeros(n_rigid), -c @ dq]))
