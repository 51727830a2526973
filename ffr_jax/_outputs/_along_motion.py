"""Accelerations and joint forces at the output times of a simulation."""

import equinox as eqx
import jax

from .._dynamics._case import Case
from .._dynamics._problem import Problem
from .._dynamics._simulate import Trajectory
from ._accelerations import redundant_accelerations
from ._joint_forces import JointForce, joint_forces_at


def _problem(target, x, where: str) -> Problem:
    if isinstance(target, Problem):
        if x is not None:
            raise ValueError(f"{where}(problem, trajectory) takes no design: a Problem has none.")
        return target
    if isinstance(target, Case):
        if x is None:
            raise ValueError(f"{where}(case, trajectory, x) needs the design x the trajectory was simulated at.")
        return target.problem_for(x)
    raise ValueError(f"{where} takes an ffr_jax.Problem or a case with its design, got {type(target).__name__}.")


def _check_trajectory(problem: Problem, trajectory, where: str) -> None:
    if not isinstance(trajectory, Trajectory):
        raise ValueError(f"{where} takes the ffr_jax.Trajectory of ffr_jax.simulate, got {type(trajectory).__name__}.")
    n = problem.scene.n_coordinates
    if trajectory.positions.shape[-1] != n:
        raise ValueError(f"The trajectory has {trajectory.positions.shape[-1]} redundant coordinates, the "
                         f"problem's scene {n}: simulate this problem (or case and design) first.")


@eqx.filter_jit
def _accelerations(problem: Problem, ts, positions, velocities):
    return jax.vmap(lambda t, y, z: redundant_accelerations(problem.model, t, y, z, problem.scene))(
        ts, positions, velocities)


@eqx.filter_jit
def _joint_forces(problem: Problem, ts, positions, velocities):
    return jax.vmap(lambda t, y, z: joint_forces_at(problem.model, t, y, z, problem.scene))(ts, positions, velocities)


def accelerations(target, trajectory: Trajectory, x=None):
    """Redundant accelerations `zdot_r` at the output times of `trajectory`, `(n_t, n_r)`.

    From the minimal equations of motion (paper eq. 15) and the acceleration constraints (eq. 13);
    see [`redundant_accelerations`][]. Differentiable (a pure function of the trajectory and `p`).

    **Arguments:**
    - `target`: the [`Problem`][] that was simulated, or a case followed by the design `x`.
    - `trajectory`: the [`Trajectory`][] of [`simulate`][].
    """
    problem = _problem(target, x, "ffr_jax.accelerations")
    _check_trajectory(problem, trajectory, "ffr_jax.accelerations")
    return _accelerations(problem, trajectory.ts, trajectory.positions, trajectory.velocities)


def joint_forces(target, trajectory: Trajectory, x=None) -> dict[str, JointForce]:
    """Forces and torques of every joint and driver at the output times of `trajectory`.

    The multipliers of the redundant equations of motion `M zdot_r + C^T lambda = h_a`, recovered
    from the minimal-coordinate solution ([`constraint_multipliers`][]), reported in each joint's
    terms ([`JointForce`][]: the force at a revolute joint in the inertial and the body frame, the
    normal force of a point-on-line joint, the torque of a driver).

    **Arguments:**
    - `target`: the [`Problem`][] that was simulated, or a case followed by the design `x`.
    - `trajectory`: the [`Trajectory`][] of [`simulate`][] (its output times `ts`).

    **Returns:** a dict from [`joint_names`][] (e.g. `"CrankPin(rod)"`) to a [`JointForce`][] whose
    arrays have the leading axis `n_t`.

    **Example:**
    ```python
    problem = fj.cases.rigid_slider_crank()
    traj = fj.simulate(problem, ts=jnp.linspace(0.0, 1.0, 101))
    torque = fj.joint_forces(problem, traj)["AngleDriver(crank)"].torque
    ```
    """
    problem = _problem(target, x, "ffr_jax.joint_forces")
    _check_trajectory(problem, trajectory, "ffr_jax.joint_forces")
    return _joint_forces(problem, trajectory.ts, trajectory.positions, trajectory.velocities)
