"""Forward simulation of the minimal equations of motion with diffrax."""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._errors import SimulationError, error_if
from ._model import MinimalModel
from .._objective._base import AbstractIntegrand
from .._scene._scene import Scene


class Trajectory(eqx.Module):
    """Result of [`simulate`][ffr_jax.simulate].

    - `ts`: `(n_t,)` output times; `ys`, `zs`: `(n_t, f)` minimal (independent) positions and
      velocities there.
    - `positions`, `velocities`: `(n_t, n_r)` all redundant coordinates `y_r` and velocities `z_r`
      at the output times (the dependent ones from the constraints; see
      [`Scene.coordinate_names`][] for their order). [`Trajectory.marker_positions`][] gives the
      path of a body point.
    - `psi`: the objective `G(t1) + int F dt` at the final time (zero without an objective).
    - `num_steps`, `num_accepted_steps`: solver statistics.
    - `solution`: the diffrax solution (its `evaluate(t)` is the dense output when requested);
      the state is `(y, z)` or `(y, z, int F dt)`.
    """

    ts: Float[Array, " n_t"]
    ys: Float[Array, "n_t f"]
    zs: Float[Array, "n_t f"]
    positions: Float[Array, "n_t n_r"]
    velocities: Float[Array, "n_t n_r"]
    psi: Float[Array, ""]
    num_steps: Array
    num_accepted_steps: Array
    solution: diffrax.Solution

    def marker_positions(self, scene: Scene, body: int, marker: int) -> Float[Array, "n_t 2"]:
        """Inertial positions `r_P = R + A(theta) (c_P + Phi_P q)` of marker `marker` of body `body` at
        the output times, `(n_t, 2)` (elastic displacement included)."""
        return jax.vmap(lambda y_r: scene.marker_position(body, marker, y_r))(self.positions)


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


def minimal_vector_field(model: MinimalModel, t, state, scene: Scene, integrand: AbstractIntegrand | None):
    """`(y', z')` of the minimal equations of motion, with `psi' = F` appended when there is an integrand:
    the right-hand side [`solve_minimal`][] integrates, `state = (y, z)` or `(y, z, psi)`."""
    y_r, z_r, zdot = model.state_and_accelerations(t, state[0], state[1], scene)
    if integrand is None:
        return state[1], zdot
    return state[1], zdot, integrand(t, y_r, z_r, scene)


_NAN_INTEGRAND = (
    "The objective's integrand F turned NaN or inf along the motion, where the positions and velocities are "
    "finite: psi = int F dt cannot be integrated past that point, so the solver rejected every step there until "
    "its step budget ran out. Make the integrand finite on every state the motion reaches (e.g. guard a sqrt, "
    "log or division with jnp.where), and check it along the motion: ffr_jax.simulate(..., ts=...) gives the "
    "states to evaluate it at."
)


def _failed_solve(model, scene, integrand, sol, out_ts, out, last, psi, t0, t1):
    """`(positions, velocities, sol, psi)` at the output times, with a failed solve reported by its cause.

    A solve that stopped short of `t1` (diffrax's `throw=False`) has not reached some output times:
    their states are taken as the last state reached, `last = (t, y, z)` (finite, so that Newton's method
    converges there). The integrand is evaluated at that state and a short step `1e-6 (t1 - t0)` past
    it: a solve that failed at finite positions and velocities with a non-finite integrand there is the
    integrand's (the step size control rejects every step whose `psi` is NaN), named by the error; any
    other failure raises diffrax's own message (the step budget and its advice). A solve that reached
    `t1` evaluates the same two points at `t1` and raises nothing.
    """
    failed = sol.result != diffrax.RESULTS.successful
    t_last, y_last, z_last = last
    t_probe = jnp.minimum(t_last + 1e-6 * (t1 - t0), t1)
    y_probe = y_last + (t_probe - t_last) * z_last
    reached = jnp.isfinite(out_ts)
    ts_all = jnp.concatenate([jnp.where(reached, out_ts, t_last), jnp.stack([t_last, t_probe])])
    ys_all = jnp.concatenate([jnp.where(reached[:, None], out[0], y_last), jnp.stack([y_last, y_probe])])
    zs_all = jnp.concatenate([jnp.where(reached[:, None], out[1], z_last), jnp.stack([z_last, z_last])])
    positions, velocities = jax.vmap(lambda t, y, z: model.state(t, y, z, scene))(ts_all, ys_all, zs_all)
    values = jnp.stack([integrand(t, y_r, z_r, scene) for t, y_r, z_r in
                        zip((t_last, t_probe), positions[-2:], velocities[-2:])])
    states_finite = jnp.all(jnp.isfinite(positions[-2:])) & jnp.all(jnp.isfinite(velocities[-2:]))
    integrand_fault = failed & states_finite & ~jnp.all(jnp.isfinite(values))
    outputs = (positions[:-2], velocities[:-2], sol, psi)
    outputs = error_if(outputs, integrand_fault, _NAN_INTEGRAND, SimulationError)
    return sol.result.error_if(outputs, failed)


def solve_minimal(
    model: MinimalModel,
    scene: Scene,
    t0: float,
    t1: float,
    y0,
    z0,
    *,
    integrand: AbstractIntegrand | None = None,
    terminal: AbstractIntegrand | None = None,
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
    """Integrate the minimal equations of motion `(y, z)' = (z, Mbar^-1 (fbar - gammabar))` from the
    independent initial state `(y0, z0)`, with `psi = G(t1) + int F dt` alongside.

    Every array the vector field uses (those of the model, the scene and the terms) travels as
    the solve's `args`, and only arrays: diffrax's `BacksolveAdjoint` differentiates the vector
    field with respect to `args`, cannot close over traced arrays, and cannot carry empty tuples
    such as `Scene.forces = ()` through its state. See [`simulate`][ffr_jax.simulate] for the rest.
    """
    solver = diffrax.Dopri8() if solver is None else solver
    adjoint = diffrax.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    dynamic, static = eqx.partition((model, scene, integrand, terminal), eqx.is_inexact_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)

    def unpack(args):
        return eqx.combine(jax.tree_util.tree_unflatten(treedef, args), static)

    def field(t, state, args):
        model, scene_, integrand_, _ = unpack(args)
        return minimal_vector_field(model, t, state, scene_, integrand_)

    y0, z0 = jnp.asarray(y0, float), jnp.asarray(z0, float)
    state0 = (y0, z0) if integrand is None else (y0, z0, jnp.zeros((), y0.dtype))
    jumps = tuple(j for j in jump_ts if t0 < j < t1)
    if controller is None:
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
    elif type(controller) is not diffrax.PIDController:
        raise ValueError(f"controller= takes a diffrax.PIDController without jump_ts or step_ts "
                         f"(the drivers' switch times are added here), got {type(controller).__name__}.")
    controller = dataclasses.replace(controller, rtol=rtol, atol=atol, jump_ts=jnp.asarray(jumps) if jumps else None)
    # The final state is always saved (for psi and the terminal term), beside the requested times.
    if ts is None:
        saveat = diffrax.SaveAt(t1=True, dense=dense)
    else:
        saveat = diffrax.SaveAt(subs=[diffrax.SubSaveAt(ts=ts), diffrax.SubSaveAt(t1=True)], dense=dense)
    # A failed solve is reported here rather than by diffrax where the objective has an integrand, so that
    # an integrand turning NaN is named (issue 32). BacksolveAdjoint's backward solve takes the forward's
    # `throw`: there diffrax keeps raising.
    diagnose = integrand is not None and not isinstance(adjoint, diffrax.BacksolveAdjoint)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field), solver, t0, t1, dt0, state0, args=leaves, saveat=saveat,
        stepsize_controller=controller, max_steps=max_steps, adjoint=adjoint, throw=not diagnose,
    )
    if ts is None:
        out_ts, out, final, final_ts = sol.ts, sol.ys, sol.ys, sol.ts
    else:
        (out_ts, final_ts), (out, final) = sol.ts, sol.ys
    model, scene_, integrand_, terminal_ = unpack(leaves)
    psi = final[2][-1] if integrand is not None else jnp.zeros((), y0.dtype)
    if not diagnose:
        positions, velocities = jax.vmap(lambda t, y, z: model.state(t, y, z, scene_))(out_ts, out[0], out[1])
    else:
        last = (final_ts[-1], final[0][-1], final[1][-1])
        positions, velocities, sol, psi = _failed_solve(model, scene_, integrand_, sol, out_ts, out, last, psi, t0, t1)
    if terminal is not None:
        y_r1, z_r1 = model.state(jnp.asarray(t1, y0.dtype), final[0][-1], final[1][-1], scene_)
        psi = psi + terminal_(jnp.asarray(t1, y0.dtype), y_r1, z_r1, scene_)
    return Trajectory(
        ts=out_ts, ys=out[0], zs=out[1], positions=positions, velocities=velocities, psi=psi,
        num_steps=sol.stats["num_steps"], num_accepted_steps=sol.stats["num_accepted_steps"], solution=sol,
    )


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

    The lower-level form of [`ffr_jax.simulate`][] (which takes a [`Problem`][]).

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
    return solve_minimal(
        model, scene, t0, t1, y0, z0, integrand=integrand, solver=solver, rtol=rtol, atol=atol, ts=ts,
        dense=dense, max_steps=max_steps, adjoint=adjoint, jump_ts=jump_ts, dt0=dt0,
        controller=controller,
    )
