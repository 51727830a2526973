"""Geometric (centrifugal) stiffening of a flexible body under fast rotation."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractForce


class GeometricStiffening(AbstractForce):
    """Stress stiffening of body `body` by the centrifugal pre-stress of its own rotation.

    A modal floating-frame model is linear in the elastic coordinates: the axial tension that a
    fast rotation builds up in a beam (and that stiffens its bending) is a second-order effect
    of the deformation and is missing, so such a model even predicts the wrong trend (the
    centrifugal term `-theta'^2 M_qq q` of `h_omega` alone softens the bending modes; Kane, Ryan
    and Banerjee 1987). The standard correction adds the geometric stiffness of the
    quasi-static stress state of the rotation. For a rotation rate `theta'` about the frame
    origin that stress is `theta'^2 sigma_1`, `sigma_1` the stress of a unit centrifugal load, and
    the generalized force on the elastic coordinates is

    `Q_q = -theta'^2 K_geo q`,   `K_geo = Phi^T K_G(sigma_1) Phi`

    (`K_G` the finite element geometric stiffness, see `ffr_jax._design.geometric_stiffness`). For a
    slender rotating beam this reproduces Southwell's rule `omega^2 = omega_0^2 + alpha Omega^2`.
    `K_geo` is an array leaf of the scene, computed from the design by
    [`Case.scene`][], so design gradients flow through it.

    **Limits** (all first order in the pre-stress, as in the classical approach):
    - Only the centrifugal load of the frame's own rotation `theta'` is included. The pre-stress
      of the angular acceleration `theta''`, of a translational acceleration of the frame origin
      and of gravity is not: those need the accelerations, which a force of this interface does
      not see. The effect is exact (to first order) for a body spinning about its fixed frame
      origin at steady or slowly varying speed, as in the `spinning_beam` case.
    - The stress is the quasi-static one of the full centrifugal load with the supports of the
      modes, not the dynamic stress of the retained modes.
    - Only the elastic coordinates are stiffened. The matching term in the rotation equation
      (from the potential `1/2 theta'^2 q^T K_geo q`, second order in `q`) is omitted, so the
      effect is not energy-conserving when `theta` is free; with a driven `theta` its work goes
      into the driver.
    """

    body: int = eqx.field(static=True)
    modal_geometric_stiffness: Float[Array, "n_q n_q"]

    def generalized_force(self, t, y_r, z_r, scene):
        del t
        q = scene.body_coordinates(self.body, y_r)[3:]
        dtheta = scene.body_coordinates(self.body, z_r)[2]
        q_force = -(dtheta**2) * (self.modal_geometric_stiffness @ q)
        return scene.scatter(self.body, jnp.concatenate([jnp.zeros(3, q_force.dtype), q_force]))
