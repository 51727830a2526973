"""The update rules of the optimisation loop: an abstract base, and optax transformations with the
volume projection behind it."""

import abc

import equinox as eqx
import jax
import optax

from .._typing import Design
from ._volume import VolumeConstraint


class AbstractOptimizer(eqx.Module):
    """An update rule `x_k -> x_{k+1}` from the objective, the constraints and their gradients.

    A step of the loop ([`make_step`][]) evaluates `(psi, grad psi)` and, for each inequality
    constraint `g_i(x) <= 0`, `(g_i, grad g_i)` at `x_k`, then calls `update`. The state is a
    pytree of arrays (it goes into the checkpoints leaf by leaf), so a resumed run repeats an
    uninterrupted one bit for bit.

    Final subclasses: [`MMA`][] (any number of inequality constraints) and [`ProjectedOptax`][]
    (an optax transformation followed by the exact projection onto the volume constraint; no
    other constraint).
    """

    @abc.abstractmethod
    def start(self, x0: Design, beta) -> Design:
        """The first iterate from a user's start design (projected onto the feasible set or clipped
        to the bounds)."""

    @abc.abstractmethod
    def init(self, x: Design):
        """The optimizer state at the first iterate."""

    @abc.abstractmethod
    def update(self, x: Design, state, value, grad: Design, g, dg, beta):
        """`(x_new, state)` from `psi(x)`, `grad psi(x)` `(n,)`, `g(x)` `(m,)` and `dg/dx` `(m, n)`."""


class ProjectedOptax(AbstractOptimizer):
    """An optax transformation followed by the exact projection onto the volume constraint.

    `updates, state = transformation.update(grad psi, state, x)`, then
    `x_new = P(x + updates)` with `P` = [`VolumeConstraint.project`][]: every iterate meets
    `x_min <= x <= 1` and the volume exactly. This is the loop of `optax.adam` and of
    [`optimality_criteria`][]; it takes no other constraint (use [`MMA`][] for those).

    **Arguments:**
    - `transformation`: any `optax.GradientTransformation` (given `x` as `params`).
    - `volume`: the [`VolumeConstraint`][] held by projection.
    """

    transformation: optax.GradientTransformation
    volume: VolumeConstraint

    def start(self, x0, beta):
        return self.volume.project(x0, beta)

    def init(self, x):
        return self.transformation.init(x)

    def update(self, x, state, value, grad, g, dg, beta):
        del value, g, dg
        # optax mixes Python floats with int32 counters (adam's `decay ** count`), which strict
        # dtype promotion refuses; the optimizer's own arithmetic runs under standard promotion.
        with jax.numpy_dtype_promotion("standard"):
            updates, state = self.transformation.update(grad, state, x)
            y = optax.apply_updates(x, updates)
        return self.volume.project(y, beta), state
