"""A case without a design: a scene with fixed parameters, its model, time span and initial state."""

import equinox as eqx
from jaxtyping import Array, Float

from ._model import MinimalModel
from ._scene._scene import Scene


class RigidCase(eqx.Module):
    """A multibody scene whose parameters are fixed (no density design), ready to simulate.

    The counterpart of [`FlexibleRodCase`][] for scenes without a design-parameterised rod, such
    as a rigid slider–crank: `simulate(case.model, case.scene, case.t0, case.t1, case.y_r0,
    case.z_r0, jump_ts=case.jump_ts)`.

    - `scene`: the parameter pytree `p` (bodies, constraints, forces).
    - `model`: the partitioned minimal-coordinate model (it may have no independent coordinate,
      for a fully driven mechanism; its motion is then given by `model.positions(t, y, scene)`
      with an empty `y`).
    - `t0`, `t1`: time span; `y_r0`, `z_r0`: consistent redundant initial state;
      `jump_ts`: times where drivers switch pieces.
    """

    scene: Scene
    model: MinimalModel
    t0: float = eqx.field(static=True)
    t1: float = eqx.field(static=True)
    y_r0: Float[Array, " n_r"]
    z_r0: Float[Array, " n_r"]
    jump_ts: tuple[float, ...] = eqx.field(static=True, default=())
