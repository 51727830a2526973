"""Forward simulation of the minimal equations of motion with diffrax."""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._model import MinimalModel
from ._objective._base import AbstractIntegrand
from ._scene._scene import Scene


class Trajectory(eqx.Module):
    """Result of [`simulate`][].

    - `ts`: `(n_t,)` output times; `ys`, `zs`: `(n_t, f)` minimal positions and velocities there.
    - `psi`: the integral objective at the final time (zero without an integrand).
    - `num_steps`, `num_accepted_steps`: solver statistics.
    - `solution`: the diffrax solution (its `evaluate(t)` is the dense output when requested);
      the state is `(y, z)` or `(y, z, psi)`.
    """

    ts: Float[Array, " n_t"]
    ys: Float[Array, "n_t f"]
    zs: Float[Array, "n_t f"]
    psi: Float[Array, ""]
    num_steps: Array
    num_accepted_steps: Array
    solution: diffrax.Solution


def consistent_minimal_state(model: MinimalModel, scene: Scene, t0, y_r0, z_r0, tol: float = 1e-8):
    """Check that `(y_r0, z_r0)` satisfies the position and velocity constraints and return `(y0, z0)`.

    Raises (through `eqx.error_if`) when `|c| > tol (1 + |y_r0|)` or `|cdot| > tol (1 + |z_r0|)`:
    the simulation would otherwise silently start from the projected state.
    """
    y_r0 = jnp.asarray(y_r0, float)
    z_r0 = jnp.asarray(z_r0, float)
    n = scene.n_coordinates
    if y_r0.shape != (n,) or z_r0.shape != (n,):
        raise ValueError(
            f"Initial redundant positions/velocities must have shape ({n},) for this scene "
            f"(coordinates {scene.coordinate_names()}), got {y_r0.shape} and {z_r0.shape}."
        )
    t0 = jnp.asarray(t0, float)
    pos = scene.constraint_residual(t0, y_r0)
    vel = model.velocity_constraint(t0, y_r0, z_r0, scene)
    bad_pos = jnp.max(jnp.abs(pos), initial=0.0) > tol * (1.0 + jnp.max(jnp.abs(y_r0)))
    bad_vel = jnp.max(jnp.abs(vel), initial=0.0) > tol * (1.0 + jnp.max(jnp.abs(z_r0)))
    y_r0 = eqx.error_if(
        y_r0, bad_pos,
        "Inconsistent initial conditions: the initial positions violate the position constraints "
        "c(y_r0, t0) = 0 (paper eq. 19). Assemble the mechanism first (e.g. model.positions(t0, y0, scene)).",
    )
    z_r0 = eqx.error_if(
        z_r0, bad_vel,
        "Inconsistent initial conditions: the initial velocities violate the velocity constraints "
        "C z_r0 + c_t = 0 (paper eq. 19). Compute them with model.velocities(t0, y_r0, z0, scene).",
    )
    return model.split(y_r0)[0], model.split(z_r0)[0]


def simulate(
    model: MinimalModel,
    scene: Scene,
    t0: float,
    t1: float,
    y_r0,
    z_r0,
    *,
    integrand: AbstractIntegrand | None = None,
    solver: diffrax.AbstractSolver | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    ts=None,
    dense: bool = False,
    max_steps: int = 1_000_000,
    adjoint: diffrax.AbstractAdjoint | None = None,
    jump_ts: tuple[float, ...] = (),
    dt0: float | None = None,
    controller: diffrax.PIDController | None = None,
) -> Trajectory:
    """Integrate the minimal equations of motion from consistent redundant initial conditions.

    **Arguments:**
    - `model`, `scene`: the partitioned model and the parameter pytree `p`.
    - `t0`, `t1`: time span; `y_r0`, `z_r0`: `(n_r,)` consistent initial positions and velocities.
    - `integrand`: if given, `psi = int F dt` is integrated along as an extra state.
    - `solver`: any diffrax solver (default `Dopri8()`; implicit ones such as `Kvaerno5()` work too).
      Dopri8 is the default because the retained modes make the equations mildly stiff: on the
      reference case explicit 5th-order `Tsit5()` needs about 18,000 steps at every rtol from 1e-6
      to 1e-9 (its stability limit), Dopri8 4,700-6,400; at rtol 1e-10 Dopri8 runs 2.3x faster
      (benchmarks/RESULTS.md, "Forward simulation").
    - `rtol`, `atol`: PID step-size control tolerances.
    - `ts`: optional output times (default: `t1` only); `dense`: keep the dense interpolant.
    - `max_steps`: diffrax step budget (exhaustion raises diffrax's error with advice). With
      `dense=True` the dense output is stored for that many steps (about 1 KB per step with Dopri8).
    - `adjoint`: diffrax adjoint used when differentiating through the solve.
    - `jump_ts`: times where the drivers switch pieces (the step-size controller lands on them).
    - `controller`: a `diffrax.PIDController` whose settings other than the tolerances (`pcoeff`,
      `icoeff`, `norm`, `factormax`, ...) replace diffrax's defaults; its `rtol`, `atol` are
      replaced by the arguments above.

    **Returns:** a [`Trajectory`][].
    """
    y0, z0 = consistent_minimal_state(model, scene, t0, y_r0, z_r0)
    solver = diffrax.Dopri8() if solver is None else solver
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint

    # Only the arrays of the scene travel as `args` (the rest is closed over): diffrax's
    # BacksolveAdjoint cannot carry empty tuples such as `Scene.forces = ()` through its state.
    dynamic, static = eqx.partition(scene, eqx.is_inexact_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)

    def field(t, state, args):
        scene_ = eqx.combine(jax.tree_util.tree_unflatten(treedef, args), static)
        y_r, z_r, zdot = model.state_and_accelerations(t, state[0], state[1], scene_)
        if integrand is None:
            return state[1], zdot
        return state[1], zdot, integrand(t, y_r, scene_)

    state0 = (y0, z0) if integrand is None else (y0, z0, jnp.zeros((), y0.dtype))
    jumps = tuple(j for j in jump_ts if t0 < j < t1)
    if controller is None:
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
    elif type(controller) is not diffrax.PIDController:
        raise ValueError(f"simulate(controller=...) takes a diffrax.PIDController without jump_ts or step_ts "
                         f"(the drivers' switch times are added here), got {type(controller).__name__}.")
    controller = dataclasses.replace(controller, rtol=rtol, atol=atol, jump_ts=jnp.asarray(jumps) if jumps else None)
    saveat = diffrax.SaveAt(t1=ts is None, ts=ts, dense=dense)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        solver,
        t0,
        t1,
        dt0,
        state0,
        args=leaves,
        saveat=saveat,
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=adjoint,
    )
    psi = sol.ys[2][-1] if integrand is not None else jnp.zeros(())
    return Trajectory(
        ts=sol.ts,
        ys=sol.ys[0],
        zs=sol.ys[1],
        psi=psi,
        num_steps=sol.stats["num_steps"],
        num_accepted_steps=sol.stats["num_accepted_steps"],
        solution=sol,
    )
