"""The optimisation driver: the step loop with a log, checkpoints, resumption and progress."""

import json
import math
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
import numpy as np
import optax

from .._errors import FFRJaxError, SimulationError
from ._checkpoint import Checkpoint, CheckpointError, load_checkpoint, restore_opt_state, save_checkpoint
from .._optimize._fingerprint import tree_fingerprint
from ._history import History
from ._progress import Progress
from .._optimize._projection import _check_beta, beta_continuation
from .._optimize._constraint import AbstractDesignConstraint
from .._optimize._pytree import Raveled, is_flat, raveled_objective
from ._run_lock import RunLock
from .._optimize._step import as_optimizer, evaluate_constraints, make_step
from .._optimize._mma import MMA
from ._step_error import StepBackOffWarning, redo_smaller, step_error

CHECKPOINT = "checkpoint.npz"
LOG = "log.csv"


class ConstraintViolationWarning(UserWarning):
    """A run ended with a constraint violated: the constraint set may have no feasible design."""


class OptimizeResult(NamedTuple):
    """The outcome of [`optimize`][].

    - `x`: the final design; `opt_state`: the optimizer state; `history`: the [`History`][].
    - `constraints`: `(m,)` the normalised values `g_i` of the inequality constraints at the final
      design (empty for Adam and OC); `names`: their labels; `descriptions`: one line per
      constraint with the constrained quantity and its bound.
    - `feasible`: whether every `g_i <= feasibility_tolerance` at the final design.
    - `back_offs`: how many MMA updates were redone with a halved move limit because the design
      they produced could not be simulated (0 in a run whose steps all went through).
    - `grey`: the [`grey_share`][] of the final design, the share of its elements with
      `0.1 < x_phys < 0.9` (`history.grey[-1]`; NaN without a [`VolumeConstraint`][] or without a step).
    """

    x: jax.Array
    opt_state: optax.OptState
    history: History
    constraints: np.ndarray = np.zeros(0)
    names: tuple[str, ...] = ()
    descriptions: tuple[str, ...] = ()
    feasible: bool = True
    back_offs: int = 0
    grey: float = float("nan")


def optimize(fun: Callable, x0, optimizer, constraints=None, *, iterations: int, directory=None,
             resume: bool = False, checkpoint_every: int = 10, config: dict | None = None, progress: bool = True,
             callback: Callable | None = None, beta: float | Callable[[int], float] | None = None,
             stop_change: float | None = None, feasibility_tolerance: float = 1e-3,
             force_resume: bool = False) -> OptimizeResult:
    """Run up to `iterations` steps of [`make_step`][] from `x0`, with a log, checkpoints and progress.

    The start design is `optimizer`'s first iterate from `x0`: the projection onto the volume
    constraint for Adam and OC, `x0` clipped to the bounds for [`MMA`][]. With a `directory`,
    every step appends `iteration, psi, volume, max_change` and one column `g_<name>` per
    inequality constraint (its normalised value at the step's start design) to
    `directory/log.csv`, and every `checkpoint_every` steps (and after the last) the design, the
    optimizer state (for MMA: `x_{k-1}`, `x_{k-2}`, the asymptotes), the iteration and the history
    of the objective and of every constraint go to `directory/checkpoint.npz`, written atomically
    (`save_checkpoint`). `resume=True` continues from that checkpoint: the steps are
    deterministic, so the iterates are those of an uninterrupted run, bit for bit.

    At the end the constraints are evaluated at the final design; if one is violated by more than
    `feasibility_tolerance` a [`ConstraintViolationWarning`][] names it (the result's `feasible` is
    then `False`). A NaN or infinite objective, constraint or design stops the run with an error
    that names the step (the last checkpoint is kept); so does an error raised inside the step's
    compiled program (e.g. Newton's method finding that the mechanism cannot assemble with the
    design a too large update produced), as the package's [`SimulationError`][] or
    [`DesignError`][] with the step, the solver's reason and what to change. With [`MMA`][] a
    design that cannot be simulated first makes the run back off: the update that produced it is
    redone with half the move limit (up to four times, a `StepBackOffWarning` each time; the
    result's `back_offs` counts them), then the run goes on with the optimizer's own limit.

    **Arguments:**
    - `fun`: `x -> (value, grad)` ([`make_objective`][] or any other).
    - `x0`: `(n_design,)` start design, or a dict `{body name: (n_b,)}` (a [`DesignMap`][]'s
      design of several bodies): flattened for the loop (`jax.flatten_util.ravel_pytree`, bodies
      in sorted name order; the checkpoint stores the flat vector, `callback` gets the dict), `fun` and the constraints are given the dict, and the result's `x` is a dict.
      Needs [`MMA`][]; a constraint on one body is [`OnBody`][], a volume shared by the bodies a
      [`VolumeConstraint`][] with a dict of filters.
    - `optimizer`: an `optax.GradientTransformation` (Adam, [`optimality_criteria`][]) or [`MMA`][].
    - `constraints`: for an optax optimizer the [`VolumeConstraint`][] it projects onto; for MMA
      one constraint or a sequence ([`VolumeConstraint`][], [`MassConstraint`][],
      [`FrequencyConstraint`][], [`FunctionConstraint`][]).
    - `iterations`: total number of steps of the run (a resumed run counts the earlier ones).
    - `directory`: where the log and the checkpoints go (created if needed); `None` writes nothing.
    - `resume`: continue the run stored in `directory`. The checkpoint holds fingerprints of the
      objective (for [`make_objective`][]: the case with its mesh and body data, filter,
      projection, method and tolerances), of the constraints (bounds, filters) and of the
      optimizer (e.g. MMA's move limit); a resume whose objects differ is refused.
    - `force_resume`: resume even when those fingerprints or the `config` settings differ (the run then
      continues with the objects and settings given now, with a warning naming the settings that changed,
      and its later checkpoints store the new ones).
    - `checkpoint_every`: steps between checkpoints.
    - `config`: JSON-serialisable settings that define the run (stored in each checkpoint; a
      resume with different settings is refused, and so is one with other constraints).
    - `progress`: show progress on standard error (a tqdm bar on a terminal, plain lines otherwise).
    - `callback`: called as `callback(iteration, x, info)` after each step.
    - `beta`: the sharpness of the constraints' and `fun`'s [`HeavisideProjection`][], if they
      have one: a number, or a schedule `k -> beta_k` such as [`beta_continuation`][] (step `k`
      runs with `beta_k`; the start design is projected with `beta_0`). A schedule is a function
      of `k` alone, so a resumed run repeats the uninterrupted one. Left out while the objective
      ([`make_objective`][] with `projection=`) or a constraint has a projection, the run takes the
      default continuation `fj.beta_continuation()` (1, 2, 4, ..., 32, doubled every 10 steps), the
      same as `ffr-jax optimize --optimizer mma`, so that a long enough run ends with a 0/1 design
      (the history's and the result's `grey` say how close it came).
    - `stop_change`: stop early once a step changes no variable by more than this (top88's 0.01);
      the test looks at the logged history only, so a resumed run stops where the uninterrupted
      one did.
    - `feasibility_tolerance`: the largest normalised violation `g_i` still called feasible.

    **Returns:** an [`OptimizeResult`][].

    A run owns its `directory` while it runs (an exclusive lock, `RunLock`): a second run in the
    same directory, started while the first runs, is refused at once.

    **Raises:** [`CheckpointError`][] when `resume` finds no readable checkpoint or one from
    other settings, when a fresh run would overwrite one, or when another process runs in
    `directory`; `FloatingPointError` on a NaN.
    """
    if directory is None or (resume and not Path(directory).is_dir()):  # nothing to own (or to resume)
        return _optimize(fun, x0, optimizer, constraints, iterations=iterations, directory=directory, resume=resume,
                         checkpoint_every=checkpoint_every, config=config, progress=progress, callback=callback,
                         beta=beta, stop_change=stop_change, feasibility_tolerance=feasibility_tolerance,
                         force_resume=force_resume)
    Path(directory).mkdir(parents=True, exist_ok=True)
    with RunLock(directory):
        return _optimize(fun, x0, optimizer, constraints, iterations=iterations, directory=directory, resume=resume,
                         checkpoint_every=checkpoint_every, config=config, progress=progress, callback=callback,
                         beta=beta, stop_change=stop_change, feasibility_tolerance=feasibility_tolerance,
                         force_resume=force_resume)


def _optimize(fun, x0, optimizer, constraints, *, iterations, directory, resume, checkpoint_every, config, progress,
              callback, beta, stop_change, feasibility_tolerance, force_resume) -> OptimizeResult:
    """[`optimize`][] in a directory this process owns (or without one)."""
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}.")
    if checkpoint_every < 1:
        raise ValueError(f"checkpoint_every must be >= 1, got {checkpoint_every}.")
    if resume and directory is None:
        raise ValueError("resume=True needs the directory of the run to resume.")
    config = json.loads(json.dumps(config or {}, sort_keys=True))
    config.pop(FINGERPRINT, None)  # the driver's own entry, which `_save` stores beside the config
    objective_print = getattr(fun, "fingerprint", None)  # set by make_objective; None for a user's function
    design_size = getattr(fun, "design_size", None)  # likewise: the case's number of densities
    if beta is None and _has_projection(fun, constraints):
        beta = beta_continuation()
    beta_of = _beta_schedule(beta)
    unravel = None
    if not is_flat(x0):  # a design of several bodies: one flat vector inside the loop
        x0, unravel = ravel_pytree(jax.tree.map(lambda a: jnp.asarray(a, dtype=jnp.float64), x0))
        fun = raveled_objective(fun, unravel)
        if isinstance(constraints, AbstractDesignConstraint):
            constraints = (constraints,)
        constraints = tuple(Raveled(c, unravel) for c in (constraints or ()))
        if isinstance(optimizer, optax.GradientTransformation):
            raise ValueError("A design of several bodies (a dict) needs fj.MMA(): the volume projection of Adam "
                             "and OC holds the volume of one design vector.")
        if callback is not None:
            user_callback = callback

            def callback(k, x, info):
                user_callback(k, unravel(x), info)
    optimizer, constraints = as_optimizer(optimizer, constraints)
    names = _unique_names(constraints)
    fingerprint = {"objective": objective_print, "constraints": tree_fingerprint(constraints),
                   "optimizer": tree_fingerprint(optimizer)}

    x = optimizer.start(jnp.asarray(x0, dtype=jnp.float64), beta_of(0))
    opt_state = optimizer.init(x)
    history = History.empty(names)
    directory = None if directory is None else Path(directory)
    if resume:
        checkpoint = load_checkpoint(directory / CHECKPOINT)
        _check_resume(checkpoint, config, fingerprint, force_resume, directory)
        if checkpoint.history.names != names:
            raise CheckpointError(f"Cannot resume: the run was made with the constraints "
                                  f"{list(checkpoint.history.names)}, now {list(names)}.")
        if checkpoint.x.shape != x.shape:
            raise CheckpointError(f"The checkpoint's design has shape {checkpoint.x.shape}, this run's {x.shape}.")
        x = jnp.asarray(checkpoint.x)
        config = {**config, FINGERPRINT: fingerprint}
        opt_state = restore_opt_state(checkpoint.opt_state_leaves, opt_state)
        history = checkpoint.history
    elif directory is not None:
        config = {**config, FINGERPRINT: fingerprint}
        directory.mkdir(parents=True, exist_ok=True)
        if (directory / CHECKPOINT).exists():
            raise CheckpointError(
                f"{directory} already holds a run ({CHECKPOINT}); resume it or choose another directory."
            )
        _save(directory, 0, x, opt_state, history, config)

    log = None
    if directory is not None:
        _write_log(directory / LOG, history)
        log = open(directory / LOG, "a")
    step = make_step(fun, optimizer, constraints)
    _check_design_size(design_size, x)
    bar = Progress(iterations, history.steps, progress)
    if history.steps < iterations:
        bar.compiling()
    previous, back_offs = None, 0
    try:
        for k in range(history.steps, iterations):
            if stop_change is not None and history.steps and history.change[-1] <= stop_change:
                if log is not None and history.steps % checkpoint_every:  # keep the last step
                    _save(directory, history.steps, x, opt_state, history, config)
                break
            halvings = 0
            while True:
                try:
                    x_new, state_new, info = step(x, opt_state, beta_of(k))
                    value, volume, change = float(info.value), float(info.volume), float(info.change)
                    grey = float(info.grey)
                    g = np.asarray(info.constraints, dtype=float)
                    break
                except (FFRJaxError, eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError, ValueError) as err:
                    clean = step_error(k, err, history.steps)  # the step and the reason, not XLA's traceback
                    if clean is None:
                        raise
                    if not (isinstance(clean, SimulationError) and isinstance(optimizer, MMA) and previous):
                        raise clean from None
                    # x_k (from step k - 1's update) cannot be simulated: redo that update with half the move.
                    halvings += 1
                    x, opt_state, history = redo_smaller(lambda o, c: make_step(fun, o, c), optimizer, constraints,
                                                         previous, beta_of(k - 1), history, halvings, k, clean)
                    back_offs += 1
                    warnings.warn(f"Step {k}: the design from step {k - 1}'s update could not be simulated (the step "
                                  f"was too large); that update was redone with the move limit "
                                  f"{optimizer.move / 2 ** halvings:g}.", StepBackOffWarning, stacklevel=2)
                    if log is not None:
                        log.close()
                        _write_log(directory / LOG, history)
                        log = open(directory / LOG, "a")
                        if k % checkpoint_every == 0:
                            _save(directory, k, x, opt_state, history, config)
            _check_finite(k, value, g, names, x_new, history.steps)
            previous = (x, opt_state)  # step k's start, for redoing its update if x_{k+1} fails
            x, opt_state = x_new, state_new
            history = history.append(value, volume, change, g, grey)
            if log is not None:
                log.write(_log_row(k, value, volume, change, g))
                log.flush()
                if (k + 1) % checkpoint_every == 0 or k + 1 == iterations:
                    _save(directory, k + 1, x, opt_state, history, config)
            if callback is not None:
                callback(k, x, info)
            bar.update(k + 1, _postfix(value, volume, change, g, grey))
    finally:
        if log is not None:
            log.close()
        bar.close()
    result = _finish(x, opt_state, history, constraints, names, beta_of(max(history.steps - 1, 0)),
                     feasibility_tolerance)._replace(back_offs=back_offs)
    if history.steps:
        result = result._replace(grey=float(history.grey_values[-1]))
    return result if unravel is None else result._replace(x=unravel(result.x))


def _finish(x, opt_state, history, constraints, names, beta, tolerance) -> OptimizeResult:
    """The constraints at the final design, a warning for each violated one, and the result."""
    if not constraints:
        return OptimizeResult(x, opt_state, history)
    g = np.asarray(jax.jit(lambda x, beta: evaluate_constraints(constraints, x, beta)[0])(x, beta), dtype=float)
    descriptions = tuple(c.describe(float(v)) for c, v in zip(constraints, g, strict=True))
    feasible = bool(np.all(g <= tolerance))
    if not feasible:
        violated = [f"{name}: {text}" for name, text, v in zip(names, descriptions, g, strict=True) if v > tolerance]
        warnings.warn(
            f"The run ended with {len(violated)} constraint(s) violated by more than {tolerance:g} (normalised): "
            + "; ".join(violated) + ". Either more iterations are needed, or the constraints admit no design "
            "together (check that the bounds do not contradict each other).",
            ConstraintViolationWarning, stacklevel=3,
        )
    return OptimizeResult(x, opt_state, history, g, names, descriptions, feasible)


def _unique_names(constraints) -> tuple[str, ...]:
    names, seen = [], {}
    for c in constraints:
        base = "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in c.name) or "g"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}_{seen[base]}")
    return tuple(names)


def _check_finite(k, value, g, names, x_new, saved_steps):
    bad = []
    if not math.isfinite(value):
        bad.append(f"psi = {value}")
    bad += [f"g_{name} = {v}" for name, v in zip(names, g, strict=True) if not math.isfinite(v)]
    if not bool(jnp.all(jnp.isfinite(x_new))):
        bad.append("the updated design has non-finite entries")
    if bad:
        raise FloatingPointError(
            f"Step {k} of the optimisation produced " + ", ".join(bad) + ". The objective or a constraint cannot be "
            "evaluated at this design (e.g. a failed solve or a singular modal analysis); the run stops here. "
            f"The last checkpoint (if any) holds an earlier iterate; {saved_steps} step(s) were complete."
        )


def _postfix(value, volume, change, g, grey=math.nan) -> str:
    text = f"psi {value:.4e}"
    if not math.isnan(volume):
        text += f" V {volume:.4f}"
    if not math.isnan(grey):
        text += f" grey {100 * grey:.1f}%"
    if g.size:
        text += f" max g {g.max():+.2e}"
    return text + f" change {change:.2e}"


def _check_design_size(design_size, x) -> None:
    """`x0` has the number of densities of the objective's case ([`make_objective`][] records it), or a
    `ValueError` before anything is compiled. (For a user's function, the step checks the gradient's shape
    against the design's when it is traced, `ffr_jax._optimize._step`.) An `x0` of the wrong length
    otherwise failed inside the optimizer's update, after the objective had compiled, with a
    broadcasting `TypeError`."""
    if design_size is not None and x.size != design_size:
        raise ValueError(
            f"The start design x0 has {x.size} densities, but the objective's case has {design_size}: x0 must be a "
            "design of the case the objective was made from (e.g. case.initial_design(0.5))."
        )


def _has_projection(fun, constraints) -> bool:
    """Whether the objective ([`make_objective`][] records its projection) or a constraint (inside
    `OnBody`/`Raveled`) has a Heaviside projection, and so needs a `beta`."""
    if getattr(fun, "projection", None) is not None:
        return True
    if isinstance(constraints, AbstractDesignConstraint):
        constraints = (constraints,)
    for c in constraints or ():
        while hasattr(c, "constraint"):
            c = c.constraint
        if getattr(c, "projection", None) is not None:
            return True
    return False


def _beta_schedule(beta) -> Callable:
    """`k -> beta_k` as a float64 array (`None` when there is no projection); one dtype, so no retrace."""
    if beta is None:
        return lambda k: None
    if callable(beta):
        return lambda k: jnp.asarray(_check_beta(beta(k), f"optimize(beta=schedule): the schedule's beta at step {k}"),
                                     dtype=jnp.float64)
    value = _check_beta(beta, "optimize(beta=...)")
    return lambda k: jnp.asarray(value, dtype=jnp.float64)


def _save(directory, iteration, x, opt_state, history, config):
    leaves = tuple(jax.device_get(leaf) for leaf in jax.tree_util.tree_leaves(opt_state))
    config = dict(config)
    fingerprint = config.pop(FINGERPRINT, None)  # carried in `config` inside the driver; stored beside it
    save_checkpoint(directory / CHECKPOINT, Checkpoint(iteration, jax.device_get(x), leaves, history, config,
                                                       fingerprint))


# The key of the fingerprints in the driver's config (stored as the checkpoint's `fingerprint`; see `_check_resume`).
FINGERPRINT = "_fingerprint"
_WHAT = {"objective": "objective (case, mesh, body data, filter, projection, method or tolerances)",
         "constraints": "constraints (bounds, filters, projections)", "optimizer": "optimizer settings"}


def _check_resume(checkpoint: Checkpoint, given: dict, fingerprint: dict, force: bool, directory) -> None:
    """The settings agree with the checkpoint's, and (unless `force`) so do the fingerprints of the objects."""
    stored_print = checkpoint.fingerprint
    if force:  # continue with what is given now; say which settings changed
        changed = _config_changes(checkpoint.config, given)
        if changed:
            warnings.warn(f"Resuming {directory} with changed settings (force_resume): {changed}.", stacklevel=4)
        return
    _check_config(checkpoint.config, given)
    if not isinstance(stored_print, dict):  # checkpoints written before fingerprints: settings only
        return
    differ = [key for key in ("objective", "constraints", "optimizer")
              if stored_print.get(key) is not None and fingerprint.get(key) is not None
              and stored_print.get(key) != fingerprint.get(key)]
    if differ:
        raise CheckpointError(
            f"Cannot resume {directory}: the checkpoint was made with another " + " and another ".join(
                _WHAT[key] for key in differ) + " than this run's. Resume with the objects the run was made with, "
            "start a new run in another directory, or pass force_resume=True (ffr-jax optimize --force-resume) to "
            "continue this checkpoint with the objects given now."
        )


def _config_changes(stored: dict, given: dict) -> str:
    """The settings that differ between a checkpoint and this run, as `key: checkpoint a, now b; ...` ('' if none)."""
    differ = sorted(key for key in set(stored) | set(given) if stored.get(key) != given.get(key))
    return "; ".join(f"{key}: checkpoint {stored.get(key)!r}, now {given.get(key)!r}" for key in differ)


def _check_config(stored: dict, given: dict) -> None:
    details = _config_changes(stored, given)
    if details:
        raise CheckpointError(f"Cannot resume: the run's settings differ from the checkpoint's ({details}); pass "
                              "force_resume=True (ffr-jax optimize --force-resume) to continue with the new ones.")


def _log_header(names) -> str:
    return "iteration,psi,volume,max_change" + "".join(f",g_{name}" for name in names) + "\n"


def _log_row(k: int, value: float, volume: float, change: float, g=()) -> str:
    return f"{k},{value!r},{volume!r},{change!r}" + "".join(f",{float(v)!r}" for v in g) + "\n"


def _write_log(path: Path, history: History) -> None:
    """(Re)write the log from a history, atomically (a resumed run drops rows past its checkpoint)."""
    tmp = path.with_name(f".{path.name}.tmp")
    g = history.constraint_values
    with open(tmp, "w") as f:
        f.write(_log_header(history.names))
        for k in range(history.steps):
            f.write(_log_row(k, float(history.value[k]), float(history.volume[k]), float(history.change[k]), g[k]))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
