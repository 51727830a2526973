"""One optimisation step: any optax transformation followed by the volume projection."""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, Float

from ._volume import VolumeConstraint


class StepInfo(NamedTuple):
    """What one step reports.

    - `value`: `psi` at the design the step started from.
    - `volume`: the volume fraction of the new design (`mean(H x_new)` when filtered,
      `mean(P_beta(H x_new))` when projected).
    - `change`: `max_e |x_new_e - x_e|`.
    """

    value: Float[Array, ""]
    volume: Float[Array, ""]
    change: Float[Array, ""]


def make_step(fun: Callable, optimizer: optax.GradientTransformation, constraint: VolumeConstraint) -> Callable:
    """A jit-compiled step `step(x, opt_state, beta=None) -> (x_new, opt_state, info)`.

    `(psi, g) = fun(x)` (or `fun(x, beta)` when `beta` is given: a projected design, see
    [`HeavisideProjection`][]); `updates, opt_state = optimizer.update(g, opt_state, x)`;
    `x_new = P(x + updates)` with `P` the projection onto the volume constraint
    ([`VolumeConstraint.project`][]), so every iterate satisfies `x_min <= x <= 1` and
    `mean(c x) = V`. The step is compiled on its first call and reused for every later one as
    long as `x` and `opt_state` keep their shapes and dtypes (which an optax loop does); `beta`
    is a traced argument, so a continuation that raises it does not recompile.

    **Arguments:**
    - `fun`: `x -> (value, grad)`, e.g. [`make_objective`][] or `jax.value_and_grad(f)`; with a
      projection `(x, beta) -> (value, grad)`.
    - `optimizer`: any `optax.GradientTransformation` (`optax.adam(1e-2)`,
      [`optimality_criteria`][], ...); it is given `x` as `params`.
    - `constraint`: the [`VolumeConstraint`][] (with the same projection as `fun`, if any).

    **Returns:** `step`, with `opt_state = optimizer.init(x)` to start.

    **Example:**
    ```python
    opt = optax.adam(1e-2)
    step = fj.make_step(fun, opt, constraint)
    x = constraint.project(x0)
    state = opt.init(x)
    for _ in range(50):
        x, state, info = step(x, state)
    ```
    """

    @jax.jit
    def step(x, opt_state, beta=None):
        value, grad = fun(x) if beta is None else fun(x, beta)
        # optax mixes Python floats with int32 counters (adam's `decay ** count`), which strict
        # dtype promotion refuses; the optimizer's own arithmetic runs under standard promotion.
        with jax.numpy_dtype_promotion("standard"):
            updates, opt_state = optimizer.update(grad, opt_state, x)
            y = optax.apply_updates(x, updates)
        x_new = constraint.project(y, beta)
        info = StepInfo(value=value, volume=constraint.fraction(x_new, beta), change=jnp.max(jnp.abs(x_new - x)))
        return x_new, opt_state, info

    return step
