"""Redundant accelerations `zdot_r` from the minimal equations of motion (paper eqs. 13 and 15)."""

from .._dynamics._model import MinimalModel
from .._scene._scene import Scene
from ._multipliers import constraint_multipliers


def redundant_accelerations(model: MinimalModel, t, y_r, z_r, scene: Scene):
    """`zdot_r`, `(n_r,)`: the accelerations of all redundant coordinates at a consistent state `(t, y_r, z_r)`.

    `zdot = Mbar^-1 (fbar - gammabar)` (paper eq. 15) and `zdot_r = J zdot + gammabar_r` (eq. 13): the
    dependent accelerations solve the acceleration constraints `C zdot_r + gamma = 0` with
    `gamma = (C z_r)_y z_r + 2 C_t z_r + c_tt`. Computed (and differentiated) with the multipliers,
    [`constraint_multipliers`][].
    """
    return constraint_multipliers(model, t, y_r, z_r, scene)[0]
