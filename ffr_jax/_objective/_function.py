"""A user-defined integrand."""

from collections.abc import Callable

import equinox as eqx

from ._base import AbstractIntegrand


class FunctionIntegrand(AbstractIntegrand):
    """Wraps a pure JAX function `fn(t, y_r, scene) -> scalar` as an integrand.

    Example: a tracking objective `lambda t, y_r, scene: (y_r[0] - target(t)) ** 2`.
    """

    fn: Callable = eqx.field(static=True)

    def __call__(self, t, y_r, scene):
        return self.fn(t, y_r, scene)
