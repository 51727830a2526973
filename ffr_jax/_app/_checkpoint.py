"""Checkpoints of an optimisation run, written atomically: a checkpoint is whole or absent."""

import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._history import History

_FORMAT = "ffr_jax.optimize.checkpoint/2"
_READABLE = ("ffr_jax.optimize.checkpoint/1", _FORMAT)  # /1 had no constraint history


class CheckpointError(ValueError):
    """A checkpoint is missing, corrupt, or does not belong to the run that wants to resume it."""


class Checkpoint(NamedTuple):
    """The state of a run after `iteration` completed steps.

    - `iteration`: number of completed steps; `x`: the design after them, `(n_design,)`.
    - `opt_state_leaves`: the leaves of the optimizer state (see [`restore_opt_state`][]).
    - `history`: the [`History`][] of those steps, with every constraint's values and names;
      `config`: the settings of the run (JSON data).
    - `fingerprint`: digests of the objective, constraints and optimizer that made the run (JSON
      data, see [`optimize`][]), or `None` (checkpoints written before fingerprints).

    The runs are deterministic (no random numbers), so there is no RNG state to keep.
    """

    iteration: int
    x: np.ndarray
    opt_state_leaves: tuple[np.ndarray, ...]
    history: History
    config: dict
    fingerprint: dict | None = None


def save_checkpoint(path, checkpoint: Checkpoint) -> None:
    """Write a checkpoint atomically.

    The arrays go to a temporary file in the same directory, which is flushed and `fsync`ed and
    then renamed over `path` with `os.replace` (atomic on POSIX and Windows); the directory entry
    is synced after. A crash at any moment leaves either the previous checkpoint or the new one,
    never a mixture, and no temporary file survives an exception.

    **Arguments:**
    - `path`: the checkpoint file (`.npz`); its directory must exist.
    - `checkpoint`: the `Checkpoint` to store.
    """
    path = Path(path)
    arrays = {
        "format": np.array(_FORMAT),
        "iteration": np.array(checkpoint.iteration, dtype=np.int64),
        "x": np.asarray(checkpoint.x),
        "n_opt_state": np.array(len(checkpoint.opt_state_leaves), dtype=np.int64),
        "history_value": np.asarray(checkpoint.history.value),
        "history_volume": np.asarray(checkpoint.history.volume),
        "history_change": np.asarray(checkpoint.history.change),
        "history_constraints": np.asarray(checkpoint.history.constraint_values),
        "history_grey": np.asarray(checkpoint.history.grey_values),
        "constraint_names": np.array(json.dumps(list(checkpoint.history.names))),
        "config": np.array(json.dumps(checkpoint.config, sort_keys=True)),
        **({} if checkpoint.fingerprint is None else
           {"fingerprint": np.array(json.dumps(checkpoint.fingerprint, sort_keys=True))}),
    }
    for i, leaf in enumerate(checkpoint.opt_state_leaves):
        arrays[f"opt_state_{i}"] = np.asarray(leaf)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    _fsync_directory(path.parent)


def _fsync_directory(directory: Path) -> None:
    if os.name != "posix":
        return
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def load_checkpoint(path, design_bounds: tuple[float, float] = (0.0, 1.0)) -> Checkpoint:
    """Read a checkpoint written by `save_checkpoint`, checking that it is whole and its values sound.

    **Arguments:**
    - `path`: the checkpoint file.
    - `design_bounds`: `(x_min, 1)` of the run's densities (default `(0, 1)`, which holds for every
      density design).

    **Returns:** the `Checkpoint`.

    **Raises:** [`CheckpointError`][] if the file is missing, unreadable, truncated, fails its
    CRC checks, lacks an entry, or holds values no run can have written: a design with NaN, inf
    or a density outside `design_bounds`, an optimizer state or history with NaN or inf, or a
    negative integer (step count) in the optimizer state.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(
            f"No checkpoint at {path}. Resume from the directory of an earlier run (it holds "
            f"{path.name}), or start a new run."
        )
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}  # reading checks every CRC
        if str(arrays["format"]) not in _READABLE:
            raise ValueError(f"unknown format {str(arrays['format'])!r}, expected {_FORMAT!r}")
        iteration = int(arrays["iteration"])
        names = tuple(json.loads(str(arrays["constraint_names"]))) if "constraint_names" in arrays else ()
        constraints = arrays.get("history_constraints", np.zeros((iteration, 0)))
        history = History(arrays["history_value"], arrays["history_volume"], arrays["history_change"],
                          constraints, names, arrays.get("history_grey", np.full(iteration, np.nan)))
        lengths = [len(h) for h in (*history[:4], history.grey)]
        if not all(n == iteration for n in lengths) or constraints.shape != (iteration, len(names)):
            raise ValueError(f"the history has {lengths} entries ({constraints.shape} constraint values for "
                             f"{len(names)} constraints) for {iteration} iterations")
        leaves = tuple(arrays[f"opt_state_{i}"] for i in range(int(arrays["n_opt_state"])))
        config = json.loads(str(arrays["config"]))
        fingerprint = json.loads(str(arrays["fingerprint"])) if "fingerprint" in arrays else None
        x = arrays["x"]
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as err:
        raise CheckpointError(
            f"Checkpoint {path} is corrupt or incomplete ({type(err).__name__}: {err}). "
            "It cannot be resumed; start a new run."
        ) from err
    _check_values(path, x, leaves, history, design_bounds)
    return Checkpoint(iteration, x, leaves, history, config, fingerprint)


def _check_values(path: Path, x, leaves, history: History, design_bounds) -> None:
    """The stored numbers are those of a sound run, or a [`CheckpointError`][] naming the file and the entry."""
    lo, hi = design_bounds

    def refuse(what: str) -> None:
        raise CheckpointError(f"Checkpoint {path} holds {what}, which no run writes: the file was altered or "
                              "written by a run that had failed. It cannot be resumed; start a new run (or resume "
                              "an earlier copy of the directory).")

    if not np.issubdtype(x.dtype, np.floating):
        refuse(f"a design of dtype {x.dtype}")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        refuse(f"a design with NaN or inf (entry x[{bad[0]}] and {bad.size - 1} more)")
    bad = np.flatnonzero((x < lo) | (x > hi))
    if bad.size:
        refuse(f"a design with densities outside [{lo}, {hi}] (x[{bad[0]}] = {x[bad[0]]:g}, {bad.size} in all)")
    for i, leaf in enumerate(leaves):
        if np.issubdtype(leaf.dtype, np.inexact) and not np.all(np.isfinite(leaf)):
            refuse(f"NaN or inf in optimizer state array {i}")
        if np.issubdtype(leaf.dtype, np.integer) and np.any(leaf < 0):
            refuse(f"a negative count in optimizer state array {i}")
    for name in ("value", "change", "constraints"):
        values = getattr(history, name)
        if values is not None and not np.all(np.isfinite(values)):
            refuse(f"NaN or inf in the history ({name})")
    if np.any(np.isinf(history.volume)):  # NaN is the volume of a run without a volume constraint
        refuse("inf in the history (volume)")


def restore_opt_state(leaves, like):
    """Rebuild an optimizer state from stored leaves, with the structure of `like`.

    **Arguments:**
    - `leaves`: `Checkpoint.opt_state_leaves`.
    - `like`: a state of the same optimizer, e.g. `optimizer.init(x)`.

    **Returns:** the state, with the stored values (bitwise).

    **Raises:** [`CheckpointError`][] if the number, shapes or dtypes of the leaves differ.
    """
    like_leaves, treedef = jax.tree_util.tree_flatten(like)
    if len(leaves) != len(like_leaves):
        raise CheckpointError(
            f"The checkpoint holds an optimizer state with {len(leaves)} arrays, this optimizer has "
            f"{len(like_leaves)}: was it written with another optimizer?"
        )
    for i, (stored, expected) in enumerate(zip(leaves, like_leaves, strict=True)):
        expected = jnp.asarray(expected)
        if stored.shape != expected.shape or stored.dtype != expected.dtype:
            raise CheckpointError(
                f"Optimizer state array {i} in the checkpoint is {stored.dtype}{list(stored.shape)}, "
                f"this optimizer expects {expected.dtype}{list(expected.shape)}."
            )
    return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(leaf) for leaf in leaves])
