"""Joint and driver forces in each joint's own terms, from the constraint multipliers."""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._dynamics._body_dynamics import rotate
from .._dynamics._model import MinimalModel
from .._scene._angle_driver import AngleDriver
from .._scene._ground_revolute import GroundRevolute
from .._scene._point_on_line import PointOnLine
from .._scene._prescribed_point import CrankPin
from .._scene._revolute import Revolute
from .._scene._scene import Scene
from ._multipliers import constraint_multipliers


class JointForce(eqx.Module):
    """What one joint or driver exerts, at one state or along the motion (leading axes `...`).

    Signs follow the redundant equations of motion `M zdot_r + C^T lambda = h_a`: the joint's
    generalized force on the bodies is `-C_k^T lambda_k`.

    **Fields** (`None` where the joint has no such quantity):
    - `multipliers`: `(..., n_equations)` the joint's multipliers `lambda_k` (every constraint).
    - `force`: `(..., 2)` the force on the joint's (first) body at its marker, inertial frame:
      `-lambda` of a [`Revolute`][] (on `body_i`; `body_j` receives `+lambda`), [`GroundRevolute`][]
      and [`CrankPin`][]; `-lambda n` of a [`PointOnLine`][] (`n` the line's left unit normal).
    - `force_body`: `(..., 2)` the same force in the body's floating frame, `A(theta)^T force`.
    - `normal_force`: `(...)` the signed normal force `-lambda` of a [`PointOnLine`][] along `n`.
    - `torque`: `(...)` the torque a driver delivers: `-lambda` of an [`AngleDriver`][] (on its
      body), `-(P - centre) x lambda` of a [`CrankPin`][] (the motor torque on the massless crank,
      its power `torque phi'` equals the power `lambda^T c_t` the driver puts into the mechanism).
    """

    multipliers: jax.Array
    force: jax.Array | None = None
    force_body: jax.Array | None = None
    normal_force: jax.Array | None = None
    torque: jax.Array | None = None


def joint_names(scene: Scene) -> tuple[str, ...]:
    """Names of the scene's constraints, the keys of [`joint_forces`][]: the type and the body
    names, e.g. `"CrankPin(rod)"`, `"Revolute(crank,rod)"`; a repeated name gets `#2`, `#3`, ..."""
    names, seen = [], {}
    for c in scene.constraints:
        bodies = [getattr(c, a) for a in ("body", "body_i", "body_j") if isinstance(getattr(c, a, None), int)]
        label = ",".join(scene.bodies[b].name for b in bodies if 0 <= b < len(scene.bodies))
        name = f"{type(c).__name__}({label})"
        seen[name] = seen.get(name, 0) + 1
        names.append(name if seen[name] == 1 else f"{name}#{seen[name]}")
    return tuple(names)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _joint_force(constraint, lam, t, y_r, scene: Scene) -> JointForce:
    """The [`JointForce`][] of one constraint from its multipliers `lam` at one state."""

    def on_body(body, force):
        theta = scene.body_coordinates(body, y_r)[2]
        return dict(force=force, force_body=rotate(-theta, force))

    if isinstance(constraint, Revolute):
        return JointForce(lam, **on_body(constraint.body_i, -lam))
    if isinstance(constraint, GroundRevolute):
        return JointForce(lam, **on_body(constraint.body, -lam))
    if isinstance(constraint, CrankPin):
        arm = constraint.pin(t) - constraint.centre
        return JointForce(lam, torque=-_cross(arm, lam), **on_body(constraint.body, -lam))
    if isinstance(constraint, PointOnLine):
        normal = jnp.stack([-constraint.direction[1], constraint.direction[0]])
        return JointForce(lam, normal_force=-lam[0], **on_body(constraint.body, -lam[0] * normal))
    if isinstance(constraint, AngleDriver):
        return JointForce(lam, torque=-lam[0])
    return JointForce(lam)


def joint_forces_at(model: MinimalModel, t, y_r, z_r, scene: Scene) -> dict[str, JointForce]:
    """[`JointForce`][] of every joint and driver at one consistent state `(t, y_r, z_r)`, keyed by
    [`joint_names`][]; the multipliers from [`constraint_multipliers`][]. Pure and differentiable."""
    t = jnp.asarray(t, dtype=y_r.dtype)
    _, lam = constraint_multipliers(model, t, y_r, z_r, scene)
    out, start = {}, 0
    for name, c in zip(joint_names(scene), scene.constraints):
        out[name] = _joint_force(c, lam[start : start + c.n_equations], t, y_r, scene)
        start += c.n_equations
    return out


def check_joint_name(scene: Scene, joint: str | int) -> int:
    """The index of `joint` (a name of [`joint_names`][] or an index) in `scene.constraints`, or a
    `ValueError` listing the joints of the scene."""
    names = joint_names(scene)
    if isinstance(joint, int) and not isinstance(joint, bool) and 0 <= joint < len(names):
        return joint
    if isinstance(joint, str) and joint in names:
        return names.index(joint)
    raise ValueError(f"No joint {joint!r} in this scene; its joints and drivers are {list(names)} "
                     f"(a name or an index 0..{len(names) - 1}).")
