"""Objective terms of joint and driver loads: `|torque|^p`, `|force|^p`, `|normal force|^p`."""

import equinox as eqx
import jax.numpy as jnp

from .._dynamics._model import MinimalModel, Partition
from .._outputs._joint_forces import _joint_force, check_joint_name
from .._outputs._multipliers import constraint_multipliers
from ._base import AbstractIntegrand

_QUANTITIES = ("torque", "force", "normal_force")


class JointLoad(AbstractIntegrand):
    """`F = |L(t, y_r, z_r, p)|^power`: a joint's or driver's load `L` raised to a power.

    `L` is one field of the joint's [`JointForce`][]: `"torque"` of a driver ([`AngleDriver`][],
    [`CrankPin`][]), `"force"` (the magnitude of the force vector at a revolute, ground revolute,
    crank pin or point-on-line joint) or `"normal_force"` of a [`PointOnLine`][]. As an integrand,
    `psi = int |L|^p dt`: with `power=2` the integral of the squared driving torque; `psi^(1/p)` is
    the `p`-norm of the load over time, which tends to its peak `max_t |L|` as `p` grows (its
    gradient is `(1/p) psi^(1/p - 1) grad psi`).

    The multipliers come from the minimal equations of motion ([`constraint_multipliers`][]), a pure
    function of `(t, y_r, z_r, p)`: every sensitivity method differentiates the term (the adjoint
    takes its partial derivatives `R1`, `R2` of paper eq. 25 from JAX).

    **Arguments:**
    - `target`: the [`Problem`][] or case whose scene the term measures (its coordinate partition is
      kept), or that `Partition` itself.
    - `joint`: the joint's name (see [`joint_names`][], e.g. `"CrankPin(rod)"`) or its index in
      `scene.constraints`.
    - `quantity`: `"torque"`, `"force"` or `"normal_force"`.
    - `power`: the exponent `p >= 1` (default 2).
    """

    partition: Partition
    joint: int = eqx.field(static=True)
    quantity: str = eqx.field(static=True)
    power: float = eqx.field(static=True)

    def __init__(self, target, joint: str | int, quantity: str = "torque", power: float | int = 2.0):
        from .._dynamics._case import Case
        from .._dynamics._problem import Problem

        if isinstance(target, Case):
            target = target.problem
        if isinstance(target, Problem):
            self.partition = target.model.partition
            self.joint = check_joint_name(target.scene, joint)
            constraint = target.scene.constraints[self.joint]
            probe = _joint_force(constraint, jnp.zeros(constraint.n_equations), jnp.zeros(()),
                                 jnp.zeros(target.scene.n_coordinates), target.scene)
            if quantity in _QUANTITIES and getattr(probe, quantity) is None:
                have = [q for q in _QUANTITIES if getattr(probe, q) is not None]
                raise ValueError(f"Joint {joint!r} ({type(constraint).__name__}) has no {quantity}; it has {have}.")
        elif isinstance(target, Partition):
            if isinstance(joint, bool) or not isinstance(joint, int) or joint < 0:
                raise ValueError(f"With a Partition, give the joint as its index in scene.constraints, got {joint!r}.")
            self.partition, self.joint = target, joint
        else:
            raise ValueError(f"JointLoad takes the Problem or case it measures (or its Partition), got "
                             f"{type(target).__name__}.")
        if quantity not in _QUANTITIES:
            raise ValueError(f"JointLoad quantity must be one of {_QUANTITIES}, got {quantity!r}.")
        if isinstance(power, bool) or not isinstance(power, (int, float)) or not power >= 1.0:
            raise ValueError(f"JointLoad power must be a number >= 1 (2: the square), got {power!r}.")
        self.quantity, self.power = quantity, float(power)

    def __call__(self, t, y_r, z_r, scene):
        if self.joint >= len(scene.constraints):
            raise ValueError(f"JointLoad measures joint {self.joint}, but the scene has only "
                             f"{len(scene.constraints)} constraints.")
        model = MinimalModel(partition=self.partition,
                             reference_dependent=jnp.zeros(len(self.partition.dependent), y_r.dtype))
        t = jnp.asarray(t, dtype=y_r.dtype)
        _, lam = constraint_multipliers(model, t, y_r, z_r, scene)
        start = sum(c.n_equations for c in scene.constraints[: self.joint])
        constraint = scene.constraints[self.joint]
        load = getattr(_joint_force(constraint, lam[start : start + constraint.n_equations], t, y_r, scene),
                       self.quantity)
        if load is None:
            raise ValueError(f"Joint {self.joint} ({type(constraint).__name__}) has no {self.quantity}.")
        squared = jnp.sum(load**2)
        return squared if self.power == 2.0 else squared ** (self.power / 2)
