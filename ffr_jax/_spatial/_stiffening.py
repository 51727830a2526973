"""Geometric (centrifugal) stiffening of a flexible spatial body under its own rotation."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._scene._base import AbstractForce
from .._design.solid_geometric_stiffness import angular_velocity_products
from ._euler_parameters import angular_velocity
from ._flexible_body_data import SpatialFlexibleBodyData


class SpatialGeometricStiffening(AbstractForce):
    """Stress stiffening of the flexible spatial body `body` by the centrifugal pre-stress of its own rotation.

    The spatial counterpart of [`GeometricStiffening`][] (whose docstring explains why a modal floating-frame model
    needs it: without it a fast-turning beam's bending modes are softened by the rotation and even diverge). The
    quasi-static centrifugal load of the body-frame angular velocity `omega` is linear in its six products
    `pi = (omega_x^2, omega_y^2, omega_z^2, omega_y omega_z, omega_x omega_z, omega_x omega_y)`, so its geometric
    stiffness is `K_geo(omega) = sum_k pi_k K_k` with the six modal matrices `K_k` of the unit load cases (Wallrapp
    1994; `ffr_jax._design.solid_geometric_stiffness`), and the generalized force on the elastic coordinates is

    `Q_q = -K_geo(omega) q`,   `omega = 2 H(p) p'` (body frame).

    `modal_geometric_stiffness` `(6, n_q, n_q)` is an array leaf computed from the design, so it carries design
    gradients: [`solid_centrifugal_geometric_stiffness`][] for a hexahedral solid body; for a planar design lifted
    into space the [`DesignMap`][] computes it (`ffr_jax._spatial._lifted_stiffening`: the in-plane cases; the two
    out-of-plane ones vanish), so a scene template may hold zeros.

    **Limits** (first order in the pre-stress, as the planar effect):
    - Only the centrifugal load of the frame's own angular velocity about the frame origin is included; the
      pre-stress of the angular acceleration, of the frame origin's acceleration and of gravity is not. Exact (to
      first order) for a body turning about a point fixed at its frame origin (a clamped root on the axis) at steady
      or slowly varying speed, as in the `spin_up_beam` case.
    - The stress is the quasi-static one of the full centrifugal load with the supports of the unit cases (the
      reference conditions of the modes), not the dynamic stress of the retained modes.
    - Only the elastic coordinates are stiffened; the matching terms in the rotation equations (from the potential
      `1/2 q^T K_geo(omega) q`, second order in `q`) are omitted: with a driven rotation their work goes into the
      driver, with a free rotation the effect is not energy-conserving.
    """

    body: int = eqx.field(static=True)
    modal_geometric_stiffness: Float[Array, "6 n_q n_q"]

    def generalized_force(self, t, y_r, z_r, scene):
        del t
        data = scene.bodies[self.body].data
        if not isinstance(data, SpatialFlexibleBodyData):
            raise ValueError(f"SpatialGeometricStiffening(body={self.body}) needs a flexible spatial body; body "
                             f"{self.body} has {type(data).__name__}. For a planar body use GeometricStiffening.")
        n_q = data.n_modes
        if self.modal_geometric_stiffness.shape != (6, n_q, n_q):
            raise ValueError(f"SpatialGeometricStiffening(body={self.body}): modal_geometric_stiffness has shape "
                             f"{self.modal_geometric_stiffness.shape}, expected (6, {n_q}, {n_q}) (six unit load "
                             "cases for the body's modes).")
        y_b, z_b = scene.body_coordinates(self.body, y_r), scene.body_coordinates(self.body, z_r)
        products = angular_velocity_products(angular_velocity(y_b[3:7], z_b[3:7]))
        q_force = -jnp.einsum("k,kqr,r->q", products, self.modal_geometric_stiffness, y_b[7:])
        return scene.scatter(self.body, jnp.concatenate([jnp.zeros(7, q_force.dtype), q_force]))
