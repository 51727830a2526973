"""Designs of several bodies (a dict by body name) in the optimisation loop.

The loop and its optimizers work on one flat vector; a design `{name: x_b}` (a [`DesignMap`][]'s)
is flattened at the loop's boundary with `jax.flatten_util.ravel_pytree` (bodies in sorted name
order) and every function of it is given the dict back ([`Raveled`][]). A constraint on one body
of such a design is [`OnBody`][]; a constraint on all of them takes the dict itself (e.g. a
[`VolumeConstraint`][] with one filter per body: the volume shared by the bodies).
"""

from collections.abc import Callable, Mapping

import equinox as eqx
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from ._constraint import AbstractDesignConstraint


def is_flat(x) -> bool:
    """Whether a design is one vector (anything but a dict by body: an array, a list of numbers)."""
    return not isinstance(x, Mapping)


class OnBody(AbstractDesignConstraint):
    """A constraint on one body of a design of several: `g(x[body])`, its gradient zero on the others.

    **Arguments:**
    - `constraint`: any constraint of that body's design vector (e.g. a [`VolumeConstraint`][]
      with the body's [`DensityFilter`][], a [`MassConstraint`][] of its [`DesignedBody`][]).
    - `body`: the body's name (a key of the design).
    - `name`: the label (default `<constraint name>_<body>`).

    **Example:**
    ```python
    volumes = [fj.OnBody(fj.VolumeConstraint(0.4, filter=filters[b]), b) for b in ("coupler", "rocker")]
    ```
    """

    constraint: AbstractDesignConstraint
    body: str = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, constraint: AbstractDesignConstraint, body: str, name: str | None = None):
        if not isinstance(constraint, AbstractDesignConstraint):
            raise ValueError(f"OnBody takes a design constraint, got {type(constraint).__name__}.")
        self.constraint = constraint
        self.body = str(body)
        self.name = f"{constraint.name}_{body}" if name is None else name

    def _part(self, x):
        if not isinstance(x, dict) or self.body not in x:
            raise ValueError(f"OnBody({self.body!r}) needs a design dict with the body {self.body!r}; got "
                             f"{sorted(x) if isinstance(x, dict) else type(x).__name__}.")
        return x[self.body]

    def value_and_grad(self, x, beta=None):
        g, grad_body = self.constraint.value_and_grad(self._part(x), beta)
        grad = {name: jnp.zeros_like(part) for name, part in x.items()}
        grad[self.body] = grad_body
        return g, grad

    def fraction(self, x, beta=None):
        """The volume fraction of the body (when the constraint is a volume)."""
        return self.constraint.fraction(self._part(x), beta)

    def physical(self, x, beta=None):
        """The body's physical densities (when the constraint is a volume)."""
        return self.constraint.physical(self._part(x), beta)

    @property
    def is_volume(self) -> bool:
        return hasattr(self.constraint, "fraction")

    def describe(self, g: float) -> str:
        return f"{self.body}: {self.constraint.describe(g)}"


class Raveled(AbstractDesignConstraint):
    """A constraint of a pytree design seen by the loop as one of the flat vector (internal)."""

    constraint: AbstractDesignConstraint
    unravel: Callable = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, constraint, unravel):
        self.constraint, self.unravel, self.name = constraint, unravel, constraint.name

    def value_and_grad(self, x, beta=None):
        g, grad = self.constraint.value_and_grad(self.unravel(x), beta)
        return g, ravel_pytree(grad)[0]

    def fraction(self, x, beta=None):
        return self.constraint.fraction(self.unravel(x), beta)

    def physical(self, x, beta=None):
        return self.constraint.physical(self.unravel(x), beta)

    def describe(self, g: float) -> str:
        return self.constraint.describe(g)


def raveled_objective(fun: Callable, unravel: Callable) -> Callable:
    """`fun` of a pytree design as a function of the flat vector: `(x_flat[, beta]) -> (value, grad_flat)`."""

    def flat(x, *beta):
        value, grad = fun(unravel(x), *beta)
        return value, ravel_pytree(grad)[0]

    # A case's objective that runs its own compiled (and kept) programs stays uncompiled around them: the
    # ravelling is cheap, and a program of its own would trace the case again in every process.
    flat.compiles_itself = getattr(fun, "compiles_itself", False)
    return flat
