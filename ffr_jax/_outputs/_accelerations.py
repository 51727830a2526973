"""Redundant accelerations `zdot_r` from the minimal equations of motion (paper eqs. 13 and 15)."""

import jax
import jax.numpy as jnp

from .._dynamics._model import MinimalModel
from .._scene._scene import Scene


def acceleration_terms(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`(zdot_r, C, h_a)` at a consistent redundant state.

    `zdot = Mbar^-1 (fbar - gammabar)` from [`MinimalModel.accelerations`][] (paper eq. 15); the
    dependent accelerations solve the acceleration constraints `C zdot_r + gamma = 0`,
    `zdot_d = -C_d^-1 (C_i zdot + gamma)` with `gamma = (C z_r)_y z_r + 2 C_t z_r + c_tt` (eq. 13).
    The constraint Jacobian `C` (`(n_c, n_r)`) and the applied forces `h_a` (`(n_r,)`, paper eq. 8)
    are returned for the multipliers, which need them too.
    """
    t = jnp.asarray(t, dtype=y_r.dtype)
    zdot = model.accelerations(t, y_r, z_r, scene)
    c = model.constraint_jacobian(t, y_r, scene)
    h = scene.applied_forces(t, y_r, z_r)
    if not model.partition.dependent:
        return zdot, c, h
    gamma = jax.jvp(lambda tt, yy: model.velocity_constraint(tt, yy, z_r, scene), (t, y_r),
                    (jnp.ones_like(t), z_r))[1]
    c_i, c_d = model.split(c.T)
    zdot_d = -jnp.linalg.solve(c_d.T, c_i.T @ zdot + gamma)
    return model.assemble(zdot, zdot_d), c, h


def redundant_accelerations(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`zdot_r`, `(n_r,)`: the accelerations of all redundant coordinates at a consistent state
    `(t, y_r, z_r)` (see `acceleration_terms`)."""
    return acceleration_terms(model, t, y_r, z_r, scene)[0]
