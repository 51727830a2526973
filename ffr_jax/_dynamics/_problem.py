"""A multibody problem: scene, time span, initial state and objective of the motion."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize
from jaxtyping import Array, Float

from ._block_triangular import dependent_blocks
from ._model import MinimalModel, Partition, _constraint_jacobian, block_hadamard_ratio, choose_partition
from .._objective._objective import Objective, as_objective
from .._scene._body_data import BodyData, _check_body_data
from .._scene._references import check_references
from .._scene._scene import Scene


class Problem(eqx.Module):
    """A multibody problem: what [`simulate`][], [`objective`][] and [`value_and_grad`][] take.

    `psi = G(t1, y_r(t1), z_r(t1), p) + int_{t0}^{t1} F(t, y_r, z_r, p) dt` of the motion of
    `scene` (the parameter pytree `p`) from the initial state `(y0, z0)` of the independent
    coordinates; the dependent coordinates and velocities follow from the constraints.

    Build one with `Problem(scene, t1, positions=..., velocities=..., objective=...)` (see
    `__init__`). Every array inside is a parameter of `psi`: the gradient
    `value_and_grad(problem)` is a pytree like the problem, with the derivatives with respect to
    the body data, spring constants, force magnitudes, law coefficients, the objective's own
    arrays and the initial state `y0`, `z0`.

    **Fields:**
    - `scene`: the [`Scene`][]; `model`: its partitioned `MinimalModel`.
    - `objective`: the [`Objective`][] (integrand `F` and/or terminal term `G`).
    - `y0`, `z0`: `(f,)` independent initial positions and velocities.
    - `t0`, `t1`: the time span (static); `jump_ts`: times where the scene's laws switch pieces
      (static; the step-size controller lands on them); `dt0`: the first step of every solve
      (static; `None`: diffrax's choice).
    """

    scene: Scene
    model: MinimalModel
    objective: Objective
    y0: Float[Array, " f"]
    z0: Float[Array, " f"]
    t0: float = eqx.field(static=True)
    t1: float = eqx.field(static=True)
    jump_ts: tuple[float, ...] = eqx.field(static=True)
    dt0: float | None = eqx.field(static=True)

    def __init__(self, scene: Scene, t1: float, *, positions, velocities=None, objective, t0: float = 0.0,
                 jump_ts: tuple[float, ...] | None = None, partition: Partition | None = None,
                 dependent_guess=None, check_terminal: bool = True, dt0: float | None = None):
        """**Arguments:**
        - `scene`: the mechanism ([`Scene`][]: bodies, joints, drivers, forces).
        - `t1`: end time; `t0`: start time (default 0).
        - `positions`: `(n_r,)` redundant initial positions (order: [`Scene.coordinate_names`][]).
          The independent entries are taken as they are; the dependent ones are a starting guess,
          solved from the position constraints by Newton's method (a `ValueError` when the
          mechanism cannot be assembled there).
        - `velocities`: `(f,)` independent initial velocities, or `(n_r,)` redundant ones whose
          dependent entries must satisfy the velocity constraints (a `ValueError` names them
          otherwise); default: at rest.
        - `objective`: an [`Objective`][], or one term (the integrand), e.g.
          `ffr_jax.KineticEnergy()`.
        - `jump_ts`: times where the drivers switch pieces (default: the breakpoints of every law
          in the scene).
        - `partition`: the coordinate partition (default: chosen from the constraint Jacobian at
          the initial positions, preferring the rigid-body coordinates as dependent ones).
        - `dependent_guess`: `(t, y, scene) -> y_d`, a starting point of Newton's method along the
          motion (default: the initial dependent positions).
        - `check_terminal`: refuse a terminal term that depends only on coordinates the
          constraints fix (at the initial state its derivative is nonzero only on coordinates
          whose rows of `dy_r/dy` and `dz_r/dz` vanish, such as a driven crank's pin): the motion
          cannot change such a term, which is almost always a mistake in the objective.
        - `dt0`: the first step size of every solve of the problem, forward and backward
          (default `None`: diffrax's, which is 0.01 s for the solves here). An explicit solver's
          first trial step must not be far outside its stability region: with elastic modes of
          several kHz (a stiff part), give about `1 / (10 omega_max)`; a trial stage far outside it
          can move the elastic coordinates so far that the position constraints have no solution.
        """
        t0, t1 = _time(t0, "t0"), _time(t1, "t1")
        if not t1 > t0:
            raise ValueError(f"The end time t1 = {t1} must be after the start time t0 = {t0}.")
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be an ffr_jax.Scene, got {type(scene).__name__}.")
        check_scene_data(scene)
        n = scene.n_coordinates
        positions = _vector(positions, n, "positions", scene)
        if partition is None:
            rigid = tuple(o + k for o in scene.offsets for k in range(3))
            partition = choose_partition(scene, t0, positions, prefer_dependent=rigid)
        f = partition.n_independent
        y0, guess = _split(partition, positions)
        redundant_velocities = None
        if velocities is None:
            z0 = np.zeros(f)
        elif np.shape(velocities) == (f,):
            z0 = _vector(velocities, f, "velocities", scene)
        else:
            redundant_velocities = _vector(velocities, n, "velocities", scene, independent=f)
            z0 = _split(partition, redundant_velocities)[0]
        model = MinimalModel(partition=partition, reference_dependent=jnp.asarray(guess),
                             dependent_guess=dependent_guess)
        y_r0, z_r0 = _assemble(model, scene, t0, jnp.asarray(y0), jnp.asarray(z0))
        if redundant_velocities is not None:
            _check_velocities(model, scene, z_r0, redundant_velocities)
        # The conditioning of C_d at the start: the reference of the dead-point test along the motion.
        conditioning, blocks = None, None
        if partition.dependent:
            blocks = dependent_blocks(scene, t0, y_r0, partition.dependent)
            c = np.asarray(_constraint_jacobian(scene, jnp.asarray(t0, float), jnp.asarray(y_r0)))
            conditioning = jnp.asarray(block_hadamard_ratio(c[:, list(partition.dependent)], blocks))
        model = MinimalModel(partition=partition, reference_dependent=jnp.asarray(_split(partition, y_r0)[1]),
                             dependent_guess=dependent_guess, reference_conditioning=conditioning,
                             dependent_blocks=blocks)
        y0, z0 = jnp.asarray(y0), jnp.asarray(z0)
        self.scene, self.model = scene, model
        self.objective = as_objective(objective)
        self.y0, self.z0 = y0, z0
        self.t0, self.t1 = t0, t1
        if jump_ts is None:
            jump_ts = scene.breakpoints
        self.jump_ts = tuple(float(j) for j in jump_ts if t0 < j < t1)
        if dt0 is not None and not 0.0 < float(dt0) < t1 - t0:
            raise ValueError(f"dt0 must lie in (0, t1 - t0) = (0, {t1 - t0}), got {dt0}.")
        self.dt0 = None if dt0 is None else float(dt0)
        _check_objective(self, y_r0, check_terminal)

    @property
    def n_independent(self) -> int:
        return self.model.partition.n_independent

    def initial_state(self):
        """The consistent redundant initial state `(y_r0, z_r0)` of the problem's scene."""
        return _initial_state(self)

    @property
    def y_r0(self):
        """Consistent redundant initial positions `(n_r,)`."""
        return self.initial_state()[0]

    @property
    def z_r0(self):
        """Consistent redundant initial velocities `(n_r,)`."""
        return self.initial_state()[1]

    def with_scene(self, scene: Scene) -> "Problem":
        """The same problem for other parameters `p` (a scene of the same structure); concrete body data are
        checked as in the constructor."""
        check_scene_data(scene)
        return eqx.tree_at(lambda p: p.scene, self, scene)

    def with_objective(self, objective, *, check_terminal: bool = True) -> "Problem":
        """The same motion with another objective (checked as in the constructor)."""
        problem = eqx.tree_at(lambda p: p.objective, self, as_objective(objective))
        _check_objective(problem, np.asarray(problem.y_r0), check_terminal)
        return problem


def check_scene_data(scene: Scene) -> None:
    """The body data of every planar body of `scene` pass `BodyData`'s value checks (finite, positive mass and
    inertia, symmetric positive definite modal mass, symmetric positive semi-definite modal stiffness, ...),
    with the body named; traced data (a design map under `jax.jit`) are let through.

    `BodyData` checks its values when it is built, but data edited with `eqx.tree_at` or returned from a
    compiled function were never built: a negative modal stiffness there made psi -4.8e152 (issue 32).
    """
    for k, body in enumerate(scene.bodies):
        if not isinstance(body.data, BodyData):
            continue
        try:
            _check_body_data(body.data)
        except ValueError as err:
            raise ValueError(f"Body {k} ({body.name!r}) of the scene: {err}") from None


def _split(partition: Partition, v_r):
    """`(v, v_d)`: the independent and dependent entries of a redundant vector (NumPy)."""
    v_r = np.asarray(v_r)
    return v_r[list(partition.independent)], v_r[list(partition.dependent)]


def _time(value, name: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}.") from None
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}.")
    return value


def _vector(value, n: int, name: str, scene: Scene, independent: int | None = None) -> np.ndarray:
    """`value` as a finite float vector of shape `(n,)`, or a `ValueError` that says what is wrong."""
    value = np.asarray(value)
    if np.iscomplexobj(value) or not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
        raise ValueError(f"The initial {name} must be real numbers, got dtype {value.dtype}.")
    value = value.astype(float)
    if value.shape != (n,):
        also = f" or ({independent},) for the independent ones" if independent is not None else ""
        raise ValueError(f"The initial {name} must have shape ({n},){also} for this scene (coordinates "
                         f"{scene.coordinate_names()}), got {value.shape}.")
    if not np.all(np.isfinite(value)):
        raise ValueError(f"The initial {name} contain NaN or inf.")
    return value


@eqx.filter_jit
def _state(model, scene, t0, y0, z0):
    return model.state(t0, y0, z0, scene)


def _assemble(model: MinimalModel, scene: Scene, t0: float, y0, z0) -> tuple[np.ndarray, np.ndarray]:
    """The consistent redundant initial state, or a `ValueError` when the mechanism cannot assemble."""
    names = scene.coordinate_names()
    try:
        y_r0, z_r0 = _state(model, scene, jnp.asarray(t0), y0, z0)
    except eqx.EquinoxRuntimeError as err:
        # Newton's method on constraints without a solution ends at a fold (singular) or without converging: either
        # way, least squares tells a mechanism that cannot close from a starting point too far from one that can.
        independent = [names[i] for i in model.partition.independent]
        gap, violated = _closest_assembly(model, scene, t0, y0)
        if violated:
            raise ValueError(
                f"The mechanism cannot be assembled at the initial state: with the independent coordinates "
                f"{independent} as given, no dependent positions satisfy the position constraints. At the closest "
                f"configuration (least squares over the dependent coordinates) these stay violated: {violated} "
                f"(largest residual {gap:.3g}). A link is too short or too long to span the distance between its "
                "joints, or a joint point or axis is misplaced: check the lengths, joint points and axes of "
                "those constraints' bodies, or start from other independent positions."
            ) from None
        if "singular" in str(err):
            reason = "the constraint Jacobian is singular there"
        else:
            reason = (f"Newton's method found no solution near the given dependent positions, although the "
                      f"constraints can be met (least squares reaches a residual of {gap:.1e})")
        raise ValueError(
            f"The initial positions cannot be made consistent: {reason}. The independent coordinates "
            f"{independent} are kept as given; give dependent positions "
            f"{[names[i] for i in model.partition.dependent]} close to an assembled configuration."
        ) from None
    return np.asarray(y_r0), np.asarray(z_r0)


@eqx.filter_jit
def _residual(scene: Scene, t, y_r):
    return scene.constraint_residual(t, y_r)


def _closest_assembly(model: MinimalModel, scene: Scene, t0: float, y0) -> tuple[float, str]:
    """Least squares over the dependent coordinates from the given ones: `(largest residual, the constraints still
    violated there)`; no constraint named when the residual reaches round-off (the mechanism does assemble).

    A residual is violated when it exceeds 1e-6 of the scale of the coordinates: Gauss-Newton (Levenberg-Marquardt)
    reaches a zero residual to about `sqrt(eps) ~ 1e-8` relative even at a double root (a configuration that just
    closes), and a mechanism that cannot close keeps a gap of its geometry's size.
    """
    dependent = list(model.partition.dependent)
    y_r = np.asarray(model.reference_dependent, dtype=float)
    base = np.zeros(scene.n_coordinates)
    base[list(model.partition.independent)] = np.asarray(y0, dtype=float)
    t = jnp.asarray(t0, float)

    def full(y_d):
        out = base.copy()
        out[dependent] = y_d
        return jnp.asarray(out)

    fit = scipy.optimize.least_squares(
        lambda y_d: np.asarray(_residual(scene, t, full(y_d))), y_r,
        jac=lambda y_d: np.asarray(_constraint_jacobian(scene, t, full(y_d)))[:, dependent], method="lm",
        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200 * (len(dependent) + 1))
    residual = np.asarray(_residual(scene, t, full(fit.x)))
    gap = float(np.max(np.abs(residual), initial=0.0))
    if not gap > 1e-6 * (1.0 + float(np.max(np.abs(fit.x), initial=0.0))):
        return gap, ""
    start, violated = 0, []
    for k, c in enumerate(scene.constraints):
        rows = residual[start:start + c.n_equations]
        start += c.n_equations
        if np.max(np.abs(rows), initial=0.0) > 1e-6 * (1.0 + float(np.max(np.abs(fit.x), initial=0.0))):
            bodies = [f"{f.name} = {scene.bodies[v].name!r}" for f in dataclasses.fields(c)
                      if f.name.startswith("body") and isinstance(v := getattr(c, f.name), int) and v >= 0]
            violated.append(f"constraint {k} {type(c).__name__}({', '.join(bodies)}) by {np.array2string(rows, precision=3)}")
    return gap, "; ".join(violated)


def _check_velocities(model, scene, z_r0, given) -> None:
    names = scene.coordinate_names()
    dep = list(model.partition.dependent)
    error = np.abs(z_r0[dep] - given[dep])
    if np.any(error > 1e-8 * (1.0 + np.max(np.abs(z_r0)))):
        wrong = [f"{names[i]} = {given[i]:.6g} (constraints: {z_r0[i]:.6g})" for i, e in zip(dep, error)
                 if e > 1e-8 * (1.0 + np.max(np.abs(z_r0)))]
        raise ValueError(
            "Inconsistent initial velocities: the dependent velocities violate the velocity constraints: "
            + ", ".join(wrong) + f". Give only the {len(model.partition.independent)} independent velocities "
            f"{[names[i] for i in model.partition.independent]}, or consistent redundant ones."
        )


@eqx.filter_jit
def _initial_state(problem: Problem):
    t0 = jnp.asarray(problem.t0, problem.y0.dtype)
    return problem.model.state(t0, problem.y0, problem.z0, problem.scene)


@eqx.filter_jit
def _terms_and_derivatives(problem: Problem):
    """Values of `F` and `G` at the initial state, and the derivatives that the terminal check needs."""
    t0 = jnp.asarray(problem.t0, problem.y0.dtype)
    model, scene, obj = problem.model, problem.scene, problem.objective
    y_r, z_r = model.state(t0, problem.y0, problem.z0, scene)
    out = {}
    if obj.integrand is not None:
        out["integrand"] = obj.integrand(t0, y_r, z_r, scene)
    if obj.terminal is not None:
        out["terminal"] = obj.terminal(t0, y_r, z_r, scene)
        g_y, g_z = jax.grad(lambda a, b: obj.terminal(t0, a, b, scene), argnums=(0, 1))(y_r, z_r)
        j_y = jax.jacfwd(lambda y: model.positions(t0, y, scene))(problem.y0)
        j_z = jax.jacfwd(lambda z: model.velocities(t0, y_r, z, scene))(problem.z0)
        out["terminal_derivatives"] = (g_y, g_z, j_y, j_z)
    return out


def _check_objective(problem: Problem, y_r0, check_terminal: bool) -> None:
    """The objective's terms are scalars and finite at the initial state; the terminal term sees the motion."""
    check_references(problem.objective, problem.scene, "objective")
    t0 = jnp.asarray(problem.t0)
    z_r0 = jnp.zeros_like(jnp.asarray(y_r0))
    for name in ("integrand", "terminal"):
        term = getattr(problem.objective, name)
        if term is None:
            continue
        try:
            shape = jax.eval_shape(lambda: term(t0, jnp.asarray(y_r0), z_r0, problem.scene)).shape
        except Exception as err:  # noqa: BLE001 - the user's function failed: say which one
            raise ValueError(f"The objective's {name} failed when called as F(t, y_r, z_r, scene): {err}") from err
        if shape != ():
            raise ValueError(f"The objective's {name} must return a scalar, got shape {shape}.")
    values = _terms_and_derivatives(problem)
    for name in ("integrand", "terminal"):
        if name in values and not np.isfinite(float(values[name])):
            raise ValueError(f"The objective's {name} is {float(values[name])} at the initial state; it must be finite.")
    if "terminal_derivatives" not in values or not check_terminal or problem.n_independent == 0:
        return
    g_y, g_z, j_y, j_z = (np.asarray(a) for a in values["terminal_derivatives"])
    names = problem.scene.coordinate_names()
    # Coordinates whose rows of dy_r/dy (dz_r/dz) vanish are fixed by the constraints: the motion cannot move them.
    fixed_y = np.max(np.abs(j_y), axis=1, initial=0.0) <= 1e-12 * max(np.max(np.abs(j_y), initial=0.0), 1.0)
    fixed_z = np.max(np.abs(j_z), axis=1, initial=0.0) <= 1e-12 * max(np.max(np.abs(j_z), initial=0.0), 1.0)
    scale = max(np.max(np.abs(g_y), initial=0.0), np.max(np.abs(g_z), initial=0.0))
    if scale == 0.0:
        return
    seen = np.concatenate([np.abs(g_y) > 1e-12 * scale, np.abs(g_z) > 1e-12 * scale])
    fixed = np.concatenate([fixed_y, fixed_z])
    if np.all(fixed[seen]):
        which = sorted({names[i % len(names)] + ("'" if i >= len(names) else "") for i in np.flatnonzero(seen)})
        raise ValueError(
            f"The terminal term depends only on coordinates that the constraints fix ({', '.join(which)}): the "
            "motion cannot change it, so it carries no information about the dynamics (its value at t1 follows "
            "from the drivers and joints alone). Put it on coordinates the motion changes, or pass "
            "check_terminal=False if it is meant as a function of the scene parameters only."
        )
