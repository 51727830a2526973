"""Kinetic energy of the whole mechanism or of some of its bodies."""

import equinox as eqx
import jax.numpy as jnp

from .._dynamics._body_dynamics import body_kinetic_energy
from ._base import AbstractIntegrand


class KineticEnergy(AbstractIntegrand):
    """`F = T = sum_b 1/2 z_b^T M_b(y_b) z_b` over the bodies `bodies` (all when `None`).

    Exact for the finite element discretisation of a flexible body (its mass matrix is paper
    eq. 8 from the standard input data). As an integrand, `int T dt`; as a terminal term, the
    kinetic energy left at `t1`.
    """

    bodies: tuple[int, ...] | None = eqx.field(static=True, default=None)

    def __call__(self, t, y_r, z_r, scene):
        del t
        which = range(len(scene.bodies)) if self.bodies is None else self.bodies
        total = jnp.zeros((), y_r.dtype)
        for b in which:
            total = total + body_kinetic_energy(scene.bodies[b].data, scene.body_coordinates(b, y_r),
                                                scene.body_coordinates(b, z_r))
        return total
