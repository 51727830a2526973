"""Integral compliance of a flexible body (paper eq. 49)."""

import equinox as eqx

from ._base import AbstractIntegrand


class Compliance(AbstractIntegrand):
    """`F = (Phi q)^T K Phi q = q^T K_qq q` of body `body` (paper eq. 49; twice its strain energy)."""

    body: int = eqx.field(static=True)

    def __call__(self, t, y_r, z_r, scene):
        del t, z_r
        y_b = scene.body_coordinates(self.body, y_r)
        q = y_b[y_b.shape[0] - scene.bodies[self.body].data.n_modes:]  # the modal coordinates come last (planar, spatial)
        return q @ scene.bodies[self.body].data.modal_stiffness @ q
