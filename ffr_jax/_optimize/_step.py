"""One optimisation step: evaluate the objective and the constraints, then update the design."""

import functools
from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, Float

from ._constraint import AbstractDesignConstraint
from ._grey import grey_share
from ._optimizer import AbstractOptimizer, ProjectedOptax
from ._pytree import OnBody, Raveled
from ._volume import VolumeConstraint


class StepInfo(NamedTuple):
    """What one step reports.

    - `value`: `psi` at the design the step started from.
    - `volume`: the volume fraction of the new design (`mean(H x_new)` when filtered,
      `mean(P_beta(H x_new))` when projected; NaN when the run has no [`VolumeConstraint`][]).
    - `change`: `max_e |x_new_e - x_e|`.
    - `constraints`: `(m,)` the normalised constraint values `g_i` at the design the step started
      from (empty for Adam and OC, which hold the volume by projection).
    - `grey`: the [`grey_share`][] of the new design's physical densities as the volume constraint sees
      them (`H x_new`, or `P_beta(H x_new)` when projected): the share of its elements with
      `0.1 < x_phys < 0.9` (NaN when the run has no [`VolumeConstraint`][]).
    """

    value: Float[Array, ""]
    volume: Float[Array, ""]
    change: Float[Array, ""]
    constraints: Float[Array, " m"]
    grey: Float[Array, ""] | float = float("nan")


def as_optimizer(optimizer, constraints) -> tuple[AbstractOptimizer, tuple[AbstractDesignConstraint, ...]]:
    """The update rule and the inequality constraints it takes, from what a user passes.

    - an `optax.GradientTransformation` (Adam, [`optimality_criteria`][]) with one
      [`VolumeConstraint`][]: the transformation followed by the projection onto the volume
      ([`ProjectedOptax`][]), no inequality constraint;
    - a [`ProjectedOptax`][] with no constraints (or its own volume constraint);
    - an optimizer that takes constraints ([`MMA`][]) with a constraint or a sequence of them,
      each an [`AbstractDesignConstraint`][] (the volume among them as an inequality).
    """
    if isinstance(constraints, AbstractDesignConstraint):
        constraints = (constraints,)
    constraints = () if constraints is None else tuple(constraints)
    for c in constraints:
        if not isinstance(c, AbstractDesignConstraint):
            raise ValueError(f"Constraints must be fj.VolumeConstraint, fj.MassConstraint, fj.FrequencyConstraint, "
                             f"fj.FunctionConstraint or another AbstractDesignConstraint, got {type(c).__name__}.")
    if isinstance(optimizer, optax.GradientTransformation):
        if len(constraints) != 1 or not isinstance(constraints[0], VolumeConstraint):
            raise ValueError(
                "An optax optimizer (Adam, optimality criteria) holds exactly one constraint, the volume, by "
                f"projecting every iterate onto it; got {[type(c).__name__ for c in constraints]}. For further "
                "constraints (mass, frequency, a function of the design) use fj.MMA()."
            )
        return ProjectedOptax(optimizer, constraints[0]), ()
    if isinstance(optimizer, ProjectedOptax):
        if constraints not in ((), (optimizer.volume,)):
            raise ValueError("ProjectedOptax holds its own volume constraint and takes no other; use fj.MMA() for "
                             "further constraints.")
        return optimizer, ()
    if isinstance(optimizer, AbstractOptimizer):
        return optimizer, constraints
    raise ValueError(f"Unknown optimizer {type(optimizer).__name__}: pass an optax.GradientTransformation "
                     "(e.g. optax.adam(0.02), fj.optimality_criteria(volume)) or fj.MMA().")


def volume_of(optimizer: AbstractOptimizer,
              constraints: Sequence[AbstractDesignConstraint]) -> AbstractDesignConstraint | None:
    """The run's volume constraint (the projection's, or the first among the inequalities, also one of a
    body or of a dict design: it has `fraction`), if any."""
    if isinstance(optimizer, ProjectedOptax):
        return optimizer.volume
    return next((c for c in constraints if _is_volume(c)), None)


def _is_volume(constraint) -> bool:
    while isinstance(constraint, (Raveled, OnBody)):
        constraint = constraint.constraint
    return isinstance(constraint, VolumeConstraint)


def evaluate_constraints(constraints: Sequence[AbstractDesignConstraint], x, beta):
    """`(g, dg/dx)`: `(m,)` values and `(m, n)` gradients of the constraints at `x`."""
    if not constraints:
        return jnp.zeros((0,), x.dtype), jnp.zeros((0, x.shape[0]), x.dtype)
    values, grads = zip(*(c.value_and_grad(x, beta) for c in constraints), strict=True)
    return jnp.stack([jnp.asarray(v, dtype=x.dtype) for v in values]), jnp.stack(grads)


def _call(fun, x, beta):
    return fun(x) if beta is None else fun(x, beta)


@functools.partial(jax.jit, static_argnames="fun")
def _objective(x, beta, *, fun):
    return _call(fun, x, beta)


class _Identity:
    """The update rule as a static jit argument, compared by the identity of its parts.

    Optimizers and constraints are pytrees with arrays (not hashable by value); steps made from the
    same objects (a resumed run, a notebook cell run again) reuse one compiled update. The cache of
    the jit holds these objects, so an `id` in a stored key cannot be taken by a new object.
    """

    def __init__(self, optimizer, constraints, volume):
        self.value = (optimizer, constraints, volume)
        parts = (optimizer.transformation, optimizer.volume) if isinstance(optimizer, ProjectedOptax) else (optimizer,)
        self.key = (type(optimizer), *map(id, parts), *map(id, constraints), id(volume))

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, _Identity) and self.key == other.key


@functools.partial(jax.jit, static_argnames="rule")
def _advance(x, state, value, grad, beta, *, rule):
    optimizer, constraints, volume = rule.value
    if jnp.shape(grad) != jnp.shape(x):  # static shapes: a clear message at trace time, not a broadcasting error
        raise ValueError(f"The objective's gradient has shape {jnp.shape(grad)}, but the design x has shape "
                         f"{jnp.shape(x)}: x0 must be a design of the objective's case (e.g. case.initial_design(0.5)).")
    g, dg = evaluate_constraints(constraints, x, beta)
    x_new, state = optimizer.update(x, state, value, grad, g, dg, beta)
    fraction = jnp.full((), jnp.nan, x.dtype) if volume is None else volume.fraction(x_new, beta)
    grey = jnp.full((), jnp.nan, x.dtype) if volume is None else grey_share(volume.physical(x_new, beta))
    info = StepInfo(value=value, volume=fraction, change=jnp.max(jnp.abs(x_new - x)), constraints=g, grey=grey)
    return x_new, state, info


def make_step(fun: Callable, optimizer, constraints=None) -> Callable:
    """A compiled step `step(x, state, beta=None) -> (x_new, state, info)`.

    `(psi, g) = fun(x)` (or `fun(x, beta)` when `beta` is given: a projected design, see
    [`HeavisideProjection`][]); with an optax optimizer
    `updates, state = optimizer.update(g, state, x)`, `x_new = P(x + updates)` with `P` the
    projection onto the volume constraint ([`VolumeConstraint.project`][]), so every iterate
    satisfies `x_min <= x <= 1` and `mean(c x) = V`; with [`MMA`][] the constraints `g_i` and
    their gradients are evaluated at `x` too and MMA's subproblem gives `x_new`. The step is two
    jit-compiled programs, `step.objective` (`fun`; one program per `fun` object, shared by all
    steps made from it; the objective of [`make_objective`][] on a case runs its own programs, which a
    later process loads from the cache instead of compiling) and `step.advance` (constraints and update; one program per optimizer and
    constraint objects), each compiled on its first call and reused for every later one as long as
    `x` and `state` keep their shapes and dtypes (which the loop does); `beta` is a traced argument,
    so a continuation that raises it does not recompile.

    **Arguments:**
    - `fun`: `x -> (value, grad)`, e.g. [`make_objective`][] or `jax.value_and_grad(f)`; with a
      projection `(x, beta) -> (value, grad)`.
    - `optimizer`: an `optax.GradientTransformation` (`optax.adam(1e-2)`,
      [`optimality_criteria`][], ...; it is given `x` as `params`), or [`MMA`][].
    - `constraints`: the [`VolumeConstraint`][] (with the same projection as `fun`, if any) for an
      optax optimizer; for MMA any sequence of constraints ([`VolumeConstraint`][],
      [`MassConstraint`][], [`FrequencyConstraint`][], [`FunctionConstraint`][]).

    **Returns:** `step`, with `state = step.optimizer.init(x)` to start (`step.optimizer` is the
    update rule, `step.constraints` the inequality constraints; for an optax optimizer its own
    `init` gives the same state).

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
    optimizer, constraints = as_optimizer(optimizer, constraints)
    volume = volume_of(optimizer, constraints)

    # Two programs: the objective alone, and constraints + update. The objective (a simulation and
    # its gradient) dominates compile time; compiled alone, and keyed on `fun` itself, it is traced
    # once per `fun` object, whatever optimizer or constraints later steps use it with. The update is
    # keyed on the optimizer and constraint objects.
    if getattr(fun, "compiles_itself", False):  # make_objective of a case: its own programs, kept between processes
        def objective(x, beta):
            return _call(fun, x, beta)
    else:
        try:
            hash(fun)
            objective = functools.partial(_objective, fun=fun)
        except TypeError:
            objective = jax.jit(lambda x, beta: _call(fun, x, beta))

    advance = functools.partial(_advance, rule=_Identity(optimizer, constraints, volume))

    def step(x, state, beta=None):
        value, grad = objective(x, beta)
        return advance(x, state, value, grad, beta)

    step.objective, step.advance = objective, advance
    step.optimizer, step.constraints = optimizer, constraints
    return step
