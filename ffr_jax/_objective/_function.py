"""A user-defined objective term."""

import inspect
from collections.abc import Callable

import equinox as eqx

from ._base import AbstractIntegrand


def _takes_velocities(fn: Callable) -> bool:
    """Whether `fn` has the signature `(t, y_r, z_r, scene)` (four positional parameters) rather
    than the positions-only `(t, y_r, scene)`."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return True
    if any(p.kind is inspect.Parameter.VAR_POSITIONAL for p in params):
        return True
    positional = [p for p in params if p.kind in (inspect.Parameter.POSITIONAL_ONLY,
                                                   inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    if len(positional) not in (3, 4):
        raise ValueError(
            f"An objective function must take (t, y_r, z_r, scene) or (t, y_r, scene), got a function of "
            f"{len(positional)} positional parameters."
        )
    return len(positional) == 4


class FunctionIntegrand(AbstractIntegrand):
    """Wraps a pure JAX function as an objective term.

    `fn(t, y_r, z_r, scene) -> scalar` (positions and velocities), or the positions-only
    `fn(t, y_r, scene)`. Example: `lambda t, y_r, z_r, scene: (z_r[0] - v_target) ** 2`.
    """

    fn: Callable = eqx.field(static=True)
    velocities: bool = eqx.field(static=True)

    def __init__(self, fn: Callable):
        if not callable(fn):
            raise ValueError(f"FunctionIntegrand needs a function, got {type(fn).__name__}.")
        self.fn = fn
        self.velocities = _takes_velocities(fn)

    def __call__(self, t, y_r, z_r, scene):
        if self.velocities:
            return self.fn(t, y_r, z_r, scene)
        return self.fn(t, y_r, scene)
