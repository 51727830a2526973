"""The optimisation driver: the step loop with a log, checkpoints, resumption and progress."""

import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from ._checkpoint import Checkpoint, CheckpointError, load_checkpoint, restore_opt_state, save_checkpoint
from ._history import History
from ._progress import progress_line
from ._step import make_step
from ._volume import VolumeConstraint

CHECKPOINT = "checkpoint.npz"
LOG = "log.csv"
_LOG_HEADER = "iteration,psi,volume,max_change\n"


class OptimizeResult(NamedTuple):
    """The outcome of [`optimize`][]: the final design `x`, the optimizer state and the [`History`][]."""

    x: jax.Array
    opt_state: optax.OptState
    history: History


def optimize(fun: Callable, x0, optimizer: optax.GradientTransformation, constraint: VolumeConstraint, *,
             iterations: int, directory=None, resume: bool = False, checkpoint_every: int = 10,
             config: dict | None = None, progress: bool = True, callback: Callable | None = None,
             beta: float | Callable[[int], float] | None = None) -> OptimizeResult:
    """Run `iterations` steps of [`make_step`][] from `x0`, with a log, checkpoints and progress.

    The start design is `x_0 = P(x0)` (the projection onto the volume constraint). With a
    `directory`, every step appends `iteration, psi, volume, max_change` to `directory/log.csv`,
    and every `checkpoint_every` steps (and after the last) the design, the optimizer state, the
    iteration and the history go to `directory/checkpoint.npz`, written atomically
    ([`save_checkpoint`][]). `resume=True` continues from that checkpoint: the steps are
    deterministic, so the iterates are those of an uninterrupted run, bit for bit.

    **Arguments:**
    - `fun`: `x -> (value, grad)` ([`make_objective`][] or any other).
    - `x0`: `(n_design,)` start design; `optimizer`: any `optax.GradientTransformation`;
      `constraint`: the [`VolumeConstraint`][].
    - `iterations`: total number of steps of the run (a resumed run counts the earlier ones).
    - `directory`: where the log and the checkpoints go (created if needed); `None` writes nothing.
    - `resume`: continue the run stored in `directory`.
    - `checkpoint_every`: steps between checkpoints.
    - `config`: JSON-serialisable settings that define the run (stored in each checkpoint; a
      resume with different settings is refused).
    - `progress`: draw a progress line on standard error.
    - `callback`: called as `callback(iteration, x, info)` after each step.
    - `beta`: the sharpness of the constraint's and `fun`'s [`HeavisideProjection`][], if they
      have one: a number, or a schedule `k -> beta_k` such as [`beta_continuation`][] (step `k`
      runs with `beta_k`; the start design is projected with `beta_0`). A schedule is a function
      of `k` alone, so a resumed run repeats the uninterrupted one.

    **Returns:** an [`OptimizeResult`][].

    **Raises:** [`CheckpointError`][] when `resume` finds no readable checkpoint or one from
    other settings, or when a fresh run would overwrite one.
    """
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}.")
    if checkpoint_every < 1:
        raise ValueError(f"checkpoint_every must be >= 1, got {checkpoint_every}.")
    if resume and directory is None:
        raise ValueError("resume=True needs the directory of the run to resume.")
    config = json.loads(json.dumps(config or {}, sort_keys=True))
    beta_of = _beta_schedule(beta)

    x = constraint.project(jnp.asarray(x0, dtype=jnp.float64), beta_of(0))
    opt_state = optimizer.init(x)
    history = History.empty()
    directory = None if directory is None else Path(directory)
    if resume:
        checkpoint = load_checkpoint(directory / CHECKPOINT)
        _check_config(checkpoint.config, config)
        if checkpoint.x.shape != x.shape:
            raise CheckpointError(f"The checkpoint's design has shape {checkpoint.x.shape}, this run's {x.shape}.")
        x = jnp.asarray(checkpoint.x)
        opt_state = restore_opt_state(checkpoint.opt_state_leaves, opt_state)
        history = checkpoint.history
    elif directory is not None:
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
    step = make_step(fun, optimizer, constraint)
    try:
        for k in range(history.steps, iterations):
            start = time.perf_counter()
            x_new, opt_state, info = step(x, opt_state, beta_of(k))
            value, volume, change = float(info.value), float(info.volume), float(info.change)
            seconds = time.perf_counter() - start
            x = x_new
            history = history.append(value, volume, change)
            if log is not None:
                log.write(_log_row(k, value, volume, change))
                log.flush()
                if (k + 1) % checkpoint_every == 0 or k + 1 == iterations:
                    _save(directory, k + 1, x, opt_state, history, config)
            if callback is not None:
                callback(k, x, info)
            if progress:
                _draw(k + 1, iterations, value, volume, change, seconds)
    finally:
        if log is not None:
            log.close()
        if progress and sys.stderr.isatty():
            sys.stderr.write("\n")
    return OptimizeResult(x, opt_state, history)


def _beta_schedule(beta) -> Callable:
    """`k -> beta_k` as a float64 array (`None` when there is no projection); one dtype, so no retrace."""
    if beta is None:
        return lambda k: None
    if callable(beta):
        return lambda k: jnp.asarray(beta(k), dtype=jnp.float64)
    if not float(beta) > 0.0:
        raise ValueError(f"The projection sharpness beta must be positive, got {beta}.")
    return lambda k: jnp.asarray(float(beta), dtype=jnp.float64)


def _save(directory, iteration, x, opt_state, history, config):
    leaves = tuple(jax.device_get(leaf) for leaf in jax.tree_util.tree_leaves(opt_state))
    save_checkpoint(directory / CHECKPOINT, Checkpoint(iteration, jax.device_get(x), leaves, history, config))


def _check_config(stored: dict, given: dict) -> None:
    differ = sorted(key for key in set(stored) | set(given) if stored.get(key) != given.get(key))
    if differ:
        details = "; ".join(f"{key}: checkpoint {stored.get(key)!r}, now {given.get(key)!r}" for key in differ)
        raise CheckpointError(f"Cannot resume: the run's settings differ from the checkpoint's ({details}).")


def _log_row(k: int, value: float, volume: float, change: float) -> str:
    return f"{k},{value!r},{volume!r},{change!r}\n"


def _write_log(path: Path, history: History) -> None:
    """(Re)write the log from a history, atomically (a resumed run drops rows past its checkpoint)."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w") as f:
        f.write(_LOG_HEADER)
        for k, row in enumerate(zip(*history, strict=True)):
            f.write(_log_row(k, *(float(v) for v in row)))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _draw(done, total, value, volume, change, seconds):
    line = progress_line(done, total, value, volume, change, seconds)
    if sys.stderr.isatty():
        sys.stderr.write("\r" + line)
    elif done == total or done % max(1, total // 10) == 0:
        sys.stderr.write(line + "\n")
    sys.stderr.flush()
