"""A bound on any function of the design that comes with its gradient."""

from collections.abc import Callable

import equinox as eqx

from .._checks import number, positive
from .._typing import Design
from ._constraint import AbstractDesignConstraint, status


class FunctionConstraint(AbstractDesignConstraint):
    """`h(x) <= bound` (or `h(x) >= bound`) for a user function `h` of the design with its gradient.

    `fun` returns `(h, dh/dx)` for the design `x`, as [`make_objective`][] does (so the objective
    of another simulation, a second load case or another operating condition, can be a
    constraint), and takes the projection's `beta` as a second argument when the run has a
    projection: `fun(x)` or `fun(x, beta)`, exactly like the objective of [`make_step`][]. It must
    be traceable (it runs inside the jit-compiled step). The constraint is
    `g = (h - bound) / scale <= 0` (`g = (bound - h) / scale` with `lower=True`), `scale = |bound|`
    by default (`1` when the bound is zero).

    **Arguments:**
    - `fun`: `x -> (h, dh/dx)` or `(x, beta) -> (h, dh/dx)`.
    - `bound`: the bound on `h`.
    - `lower`: `True` for a lower bound `h >= bound`.
    - `scale`: the normalisation of `g` (default `|bound|`, or 1 for a zero bound).
    - `name`: the label in logs and plots.

    **Example:**
    ```python
    other = fj.make_objective(fj.cases.slider_crank(speed=8 * np.pi), filter=filt)
    constraint = fj.FunctionConstraint(other, 0.05, name="psi_slow")    # psi at the lower speed <= 0.05
    ```
    """

    fun: Callable
    bound: float = eqx.field(static=True)
    lower: bool = eqx.field(static=True)
    scale: float = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, fun, bound: float, *, lower: bool = False, scale: float | None = None,
                 name: str = "function"):
        if not callable(fun):
            raise ValueError(f"FunctionConstraint needs a function x -> (value, grad), got {type(fun).__name__}.")
        self.fun = fun
        self.bound = number(bound, f"FunctionConstraint {name!r}: bound")
        self.lower = bool(lower)
        if scale is None:
            scale = abs(self.bound) if self.bound != 0.0 else 1.0
        self.scale = positive(scale, f"The scale of FunctionConstraint {name!r}")
        self.name = name

    def value_and_grad(self, x: Design, beta=None):
        h, grad = self.fun(x) if beta is None else self.fun(x, beta)
        if self.lower:
            return (self.bound - h) / self.scale, -grad / self.scale
        return (h - self.bound) / self.scale, grad / self.scale

    def describe(self, g: float) -> str:
        h = self.bound - self.scale * g if self.lower else self.bound + self.scale * g
        return f"{self.name} {h:.6g} (bound {'>=' if self.lower else '<='} {self.bound:.6g}): {status(g)}"
