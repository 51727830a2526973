"""Integral compliance of a flexible body (paper eq. 49)."""

import equinox as eqx

from ._base import AbstractIntegrand


class Compliance(AbstractIntegrand):
    """`F = (Phi q)^T K Phi q = q^T K_qq q` of body `body` (paper eq. 49; twice its strain energy)."""

    body: int = eqx.field(static=True)

    def __call__(self, t, y_r, z_r, scene):
        del t, z_r
        q = scene.body_coordinates(self.body, y_r)[3:]
        return q @ scene.bodies[self.body].data.modal_stiffness @ q
