"""The package's errors, and how errors raised inside compiled programs reach the user.

Checks of values that exist only inside a compiled program (a traced design, Newton's method
along the motion) use [`error_if`][]: `equinox.error_if` with the message registered under the
error class it stands for. Such an error leaves XLA wrapped in one of two forms:

- `equinox.EquinoxRuntimeError` (under `equinox.filter_jit`, which every public entry point
  runs, also under `jax.vmap`), whose text is a trace-time stack followed by the message;
- `jax.errors.JaxRuntimeError` (under a user's `jax.jit`), `INTERNAL: CpuCallback error calling
  callback: Traceback ...` with the message at the end of a traceback.

[`clean_errors`][] (applied to every public entry point) turns both into the package's own
error, [`DesignError`][] or [`SimulationError`][], whose text *is* the message. Around a user's
own `jax.jit` nothing of the package runs when the program executes, so the exception stays
XLA's; the log record that jax writes for the failed callback is then shortened to one line
that names the message (see `install_log_filter`, attached by the first public call), so that the message is the first thing
printed. Wrapping the user's jitted function in [`clean_errors`][] gives the clean error there too.
"""

import functools
import logging
import threading

import equinox as eqx
import jax

JaxRuntimeError = jax.errors.JaxRuntimeError


class FFRJaxError(Exception):
    """Base class of the errors that ffr_jax raises for bad input or a failed solve."""


class DesignError(FFRJaxError, ValueError):
    """A design vector is unusable: wrong shape, complex, NaN or inf, or a density outside `[x_min, 1]`."""


class SimulationError(FFRJaxError, eqx.EquinoxRuntimeError):
    """The motion cannot be computed: a dead point, Newton's method without a solution, the step
    budget used up, inconsistent initial conditions, ... (a `RuntimeError`; also an
    `equinox.EquinoxRuntimeError`, which is what such errors were before)."""


# message -> error class, for every message raised through `error_if` / `branched_error_if`.
_KINDS: dict[str, type[FFRJaxError]] = {}

_MAX_STEPS = "The maximum number of solver steps was reached"
_MAX_STEPS_ADVICE = (
    " The ODE solver used up its step budget before the end time: raise max_steps (an argument of "
    "ffr_jax.simulate / objective / value_and_grad, and Adjoint(max_steps=...) for the backward solve), "
    "loosen rtol/atol, or shorten the time span. (A mechanism that reaches a dead point is reported "
    "as a dead point, not as a step budget.)"
)


def error_if(x, pred, msg: str, kind: type[FFRJaxError]):
    """`equinox.error_if(x, pred, msg)`, with `msg` registered as an error of class `kind`."""
    _KINDS[msg] = kind
    return eqx.error_if(x, pred, msg)


def branched_error_if(x, pred, index, msgs: tuple[str, ...], kind: type[FFRJaxError]):
    """`equinox.branched_error_if`, with every message registered as an error of class `kind`."""
    for msg in msgs:
        _KINDS[msg] = kind
    return eqx.branched_error_if(x, pred, index, msgs)


# The text around the message in equinox's two wrappers (equinox 0.13).
_WRAPPERS = (
    ("equinox.EquinoxRuntimeError: ", "\n\n-------------------\n\nAn error occurred during the runtime"),
    ("_EquinoxRuntimeError: ", "\n\n\n--------------------\nAn error occurred during the runtime"),
)


def runtime_message(err: BaseException) -> str | None:
    """The message of an `equinox.error_if` inside `err` (either wrapper, or equinox's exception raised
    in the callback itself), or `None` if it holds none."""
    text = str(err)
    if type(err).__name__ == "_EquinoxRuntimeError":  # raised in the callback: its text starts with the message
        text = "_EquinoxRuntimeError: " + text
    for start, end in _WRAPPERS:
        i = text.rfind(start)
        if i < 0:
            continue
        j = text.find(end, i)
        return (text[i + len(start):j] if j >= 0 else text[i + len(start):]).strip()
    return None


def package_error(err: BaseException) -> FFRJaxError | None:
    """The package's error for a runtime error raised inside a compiled program, or `None`."""
    if isinstance(err, FFRJaxError) or not isinstance(err, (eqx.EquinoxRuntimeError, JaxRuntimeError)):
        return None
    msg = runtime_message(err)
    if msg is None:
        return None
    kind = _KINDS.get(msg, SimulationError)
    if msg.startswith(_MAX_STEPS):
        msg += _MAX_STEPS_ADVICE
    return kind(msg)


# How many public entry points are running (in any thread: XLA may run a callback on its own thread).
_depth = 0
_lock = threading.Lock()


def _enter(step: int) -> int:
    global _depth
    with _lock:
        _depth += step
        return _depth


def _inside() -> bool:
    return _depth > 0


def clean_errors(fn):
    """Decorator: errors raised inside the compiled programs that `fn` runs reach the caller as the
    package's own [`DesignError`][] or [`SimulationError`][], the message first, without the
    XLA or equinox wrapper text (and without jax's logged traceback of the failed callback).

    Applied to every public entry point. Also usable around a user's own compiled function, e.g.
    `step = ffr_jax.clean_errors(jax.jit(step))`, where the package cannot intervene otherwise:
    the outputs are waited for inside the wrapper so that the error surfaces there.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        __tracebackhide__ = True
        install_log_filter()  # on the first call of an entry point, not on import
        _enter(1)
        try:
            out = fn(*args, **kwargs)
            jax.block_until_ready(_concrete_only(out))
            return out
        except (eqx.EquinoxRuntimeError, JaxRuntimeError) as err:
            clean = package_error(err)
            if clean is None:
                raise
            raise clean from None
        finally:
            _enter(-1)

    return wrapper


def _concrete_only(tree):
    """`tree`, or `None` when it holds tracers (the caller is tracing: there is nothing to wait for)."""
    leaves = jax.tree_util.tree_leaves(tree)
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return None
    return tree


class _ShortCallbackLog(logging.Filter):
    """Shortens jax's log record of a failed callback that carries one of the package's messages.

    Inside a public entry point (and under `equinox.filter_jit`) the record is dropped: the error
    that follows carries the message. Elsewhere (a user's `jax.jit`) it becomes one line with the
    message, printed before XLA's long error.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if exc is None:
            return True
        msg = runtime_message(exc) or ""
        if msg not in _KINDS and not msg.startswith(_MAX_STEPS):
            return True
        if _inside() or any(type(f).__module__.startswith("equinox") for f in _LOGGER.filters):
            # A public entry point or equinox.filter_jit is running: the error that follows says it all.
            return False
        record.msg = ("ffr_jax: %s [raised inside a jax.jit-compiled program; the functions of ffr_jax are "
                      "compiled already and need no jax.jit; see ffr_jax.clean_errors]")
        record.args = (msg,)
        record.exc_info = None
        record.exc_text = None
        return True


_FILTER = _ShortCallbackLog()
_LOGGER = logging.getLogger("jax._src.callback")


def install_log_filter() -> None:
    """Attach the filter to jax's callback logger (idempotent; done by the first call of a public entry
    point, so that `import ffr_jax` leaves logging alone)."""
    if _FILTER not in _LOGGER.filters:
        _LOGGER.addFilter(_FILTER)
