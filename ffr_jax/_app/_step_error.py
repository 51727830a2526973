"""What a failed step of [`optimize`][] tells the user: the step, the reason, and what to change."""

from .._errors import _KINDS, DesignError, FFRJaxError, SimulationError, package_error, runtime_message

_ADVICE = (
    " The design of step {k} came from the update of step {previous}: a design that the mechanism cannot be "
    "assembled or moved with (too soft, or with disconnected material) means that update was too large. "
    "Lower the step (fj.MMA(move=...) or `ffr-jax optimize --mma-move`; fj.optimality_criteria(move=...) or "
    "--move; Adam's learning rate or --lr) and start again, or resume from the last checkpoint "
    "({saved} step(s) complete) with the smaller step."
)
_AT_START = (" This is the start design (step 0): check the scene and the start design, which the solver must be able "
             "to simulate before any update.")


def step_error(k: int, err: BaseException, saved_steps: int) -> Exception | None:
    """The package's error for `err` raised inside the compiled step `k`, with the step named and advice
    on the step size, or `None` when `err` carries no message of the package (then re-raise it).

    **Arguments:**
    - `k`: the step that failed (it evaluates the design that step `k - 1` produced).
    - `err`: the runtime error of the compiled step (equinox's or XLA's wrapper, or the package's own).
    - `saved_steps`: the steps completed and logged before it.

    **Returns:** a [`DesignError`][] or [`SimulationError`][] whose text is one short paragraph.
    """
    clean = err if isinstance(err, FFRJaxError) else package_error(err)
    if clean is None and runtime_message(err) is not None:
        # Under jax.jit, XLA may raise a failed callback as a plain ValueError ("INTERNAL: CpuCallback error").
        message = runtime_message(err)
        clean = _KINDS.get(message, SimulationError)(message)
    if clean is None:
        return None
    reason = str(clean)
    if isinstance(clean, DesignError):
        return type(clean)(f"Step {k} of the optimisation stopped: {reason}")
    advice = _AT_START if k == 0 else _ADVICE.format(k=k, previous=k - 1, saved=saved_steps)
    return type(clean)(f"Step {k} of the optimisation stopped: the design could not be simulated. The solver "
                       f"said: {reason}{advice}")


class StepBackOffWarning(UserWarning):
    """A step of [`optimize`][] produced a design that could not be simulated and was redone with half the move."""


# How often one update is redone with half the move limit before the run stops (0.2 -> 0.0125).
MAX_HALVINGS = 4


def redo_smaller(make_step, optimizer, constraints, previous, beta, history, halvings: int, k: int, reason):
    """Redo the update of step `k - 1` with `optimizer`'s move limit halved once more.

    The design `x_k` that update produced could not be simulated (`reason`, the package's error of
    step `k`). The update is repeated from `previous = (x_{k-1}, state_{k-1})` by MMA with move
    `move / 2^halvings`; the objective at `x_{k-1}` is evaluated again (its compiled program is
    reused), and the last row of `history` is replaced by this update's (same `psi` and constraint
    values, its own change). The run then goes on with the optimizer's own move limit.

    **Returns:** `(x_k, state_k, history)` of the redone update.

    **Raises:** `reason` with a note when `halvings` exceeds [`MAX_HALVINGS`][].
    """
    import numpy as np

    if halvings > MAX_HALVINGS:
        raise type(reason)(f"{reason} (The update of step {k - 1} was redone {MAX_HALVINGS} times with the move "
                           f"limit halved each time, down to {optimizer.move / 2 ** MAX_HALVINGS:g}, and its design "
                           "still could not be simulated.)") from None
    smaller = optimizer.with_move(optimizer.move / 2**halvings)
    x, state, info = make_step(smaller, constraints)(*previous, beta)
    history = history.drop_last().append(float(info.value), float(info.volume), float(info.change),
                                         np.asarray(info.constraints, dtype=float), float(info.grey))
    return x, state, history
