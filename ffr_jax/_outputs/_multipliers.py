"""Lagrange multipliers of the constraints recovered from the minimal-coordinate solution."""

import jax.numpy as jnp

from .._dynamics._model import MinimalModel
from .._scene._scene import Scene
from ._accelerations import acceleration_terms


def constraint_multipliers(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`(zdot_r, lambda)`: redundant accelerations and the multipliers of every constraint equation.

    The redundant equations of motion `M(y_r) zdot_r + C^T lambda = h_a(t, y_r, z_r)` (paper eqs.
    8–9) hold on their independent rows by the minimal equations (eq. 15, `J^T C^T = 0`); their
    dependent rows give the multipliers,

    `lambda = C_d^-T (h_a - M zdot_r)_d`,

    with `zdot_r` from [`redundant_accelerations`][]. `-C^T lambda` is the generalized force the
    joints and drivers exert on the bodies. A pure function of the state and the scene: every
    sensitivity method differentiates it.

    **Returns:** `zdot_r` `(n_r,)` and `lambda` `(n_c,)`, ordered as `scene.constraints`.
    """
    zdot_r, c, h = acceleration_terms(model, t, y_r, z_r, scene)
    if not model.partition.dependent:
        return zdot_r, jnp.zeros((0,), y_r.dtype)
    residual = h - scene.mass_matrix(y_r) @ zdot_r
    _, c_d = model.split(c.T)
    _, r_d = model.split(residual)
    return zdot_r, jnp.linalg.solve(c_d, r_d)
