"""The design gradient as a drop-in objective `x -> (psi, grad psi)` for an optimizer."""

from collections.abc import Callable

import jax
import jax.numpy as jnp

from .. import _api
from .._errors import DesignError, error_if
from .._dynamics._case import Case
from .._sensitivity._base import AbstractSensitivity
from .._design.filter import DensityFilter
from .._design.stacked import StackedFilter
from ._fingerprint import tree_fingerprint
from ._conditions import OperatingConditions
from ._projection import HeavisideProjection


def physical_densities(x, filter: DensityFilter | StackedFilter | dict[str, DensityFilter] | None,
                       projection: HeavisideProjection | None, beta=None):
    """The physical densities of a design: `P_beta(H x)`, `H x`, `P_beta(x)` or `x` (whichever map is given).

    **Arguments:**
    - `x`: `(n_design,)` design (or a dict by body); `filter`: a [`DensityFilter`][], a dict of
      them by body (for a dict design), or `None`;
      `projection`: a [`HeavisideProjection`][] or `None`; `beta`: its sharpness (needed with a projection).

    **Returns:** `(n_design,)` physical densities (with a robust projection: the blueprint's).
    """
    return _projected(x, filter, projection, beta, lambda u: projection(u, beta))


def _objective_densities(x, filter, projection, beta):
    """The densities the objective sees: [`physical_densities`][], except that a robust projection gives the
    one design its `objective` names (`HeavisideProjection.objective_design`: eroded, blueprint or dilated)."""
    return _projected(x, filter, projection, beta, lambda u: projection.objective_design(u, beta))


def _projected(x, filter, projection, beta, project):
    if isinstance(filter, dict):  # a design of several bodies, one filter each
        if not isinstance(x, dict) or set(x) != set(filter):
            raise ValueError(f"The filters are given for the bodies {sorted(filter)}: pass the design as a dict with "
                             f"these keys, got {sorted(x) if isinstance(x, dict) else type(x).__name__}.")
        x_filtered = {name: filter[name](x[name]) for name in x}
    else:
        x_filtered = x if filter is None else filter(x)
    if projection is None:
        return x_filtered
    if beta is None:
        raise ValueError("A Heaviside projection needs its sharpness: pass beta (e.g. from fj.beta_continuation).")
    return jax.tree.map(project, x_filtered)


def filtered_objective(fun: Callable,
                       filter: DensityFilter | StackedFilter | dict[str, DensityFilter] | None,
                       projection: HeavisideProjection | None = None) -> Callable:
    """An objective of the design through a density filter (and projection), with its gradient pulled back.

    For `(psi_phys, g_phys) = fun(x_phys)` returns `x -> (psi_phys(H x), H^T g_phys(H x))`, the
    value and exact gradient of `psi(x) = psi_phys(H x)`. With a projection the physical design is
    `x_phys = P_beta(H x)` and the function is `(x, beta) -> (psi_phys(x_phys), J^T g_phys(x_phys))`,
    `J = diag(P_beta'(H x)) H` (the pullback is `jax.vjp` of the same map that made `x_phys`, so
    value and gradient are consistent). With a robust projection (`eta_eroded`, `eta_dilated` given)
    the value is the p-norm of `psi` over its eroded, blueprint and dilated designs (`objective="max"`,
    three calls of `fun`), or `psi` of the one design its `objective` names (Wang, Lazarov, Sigmund
    2011; see [`HeavisideProjection`][]).

    **Arguments:**
    - `fun`: `x_phys -> (value, grad)` with `grad` shaped like `x_phys`.
    - `filter`: a [`DensityFilter`][], or `None`.
    - `projection`: a [`HeavisideProjection`][], or `None` (then the result takes `x` only).

    **Returns:** `x -> (value, grad)` (or `(x, beta) -> (value, grad)` with a projection), with
    `grad` shaped like `x`.
    """
    if projection is None:
        if filter is None:
            return fun

        def fun_of_design(x):
            if isinstance(filter, dict):  # one filter per body of a dict design
                x_phys, pullback = jax.vjp(lambda x: physical_densities(x, filter, None), x)
                value, grad = fun(x_phys)
                return value, pullback(grad)[0]
            value, grad = fun(filter(x))
            return value, filter.transpose(grad)

        return fun_of_design

    def fun_of_projected_design(x, beta):
        x_phys, pullback = jax.vjp(lambda x: _objective_densities(x, filter, projection, beta), x)
        value, grad = fun(x_phys)
        return value, pullback(grad)[0]

    def fun_of_worst_design(x, beta):
        values, grads = [], []
        for index in range(3):  # eroded, blueprint, dilated: one solve each
            x_phys, pullback = jax.vjp(
                lambda x: _projected(x, filter, projection, beta, lambda u: projection.designs(u, beta)[index]), x)
            value, grad = fun(x_phys)
            values.append(value)
            grads.append(pullback(grad)[0])
        return smooth_max(jnp.stack(values), grads)

    return fun_of_worst_design if projection.robust and projection.objective == "max" else fun_of_projected_design


# The exponent of the p-norm that stands for the largest of the robust formulation's three objective values: it
# exceeds the largest by a factor of at most 3^(1/16) = 1.071 (three equal values), by less than 0.1 % where the
# second largest is below 0.65 of it.
SMOOTH_MAX_EXPONENT = 16


def smooth_max(values, grads):
    """`(||psi||_p, sum_i (psi_i / ||psi||_p)^(p - 1) grad_i)`: the p-norm of positive values `(3,)` and its exact
    gradient from theirs (a list of pytrees), a differentiable stand-in for `max_i psi_i`."""
    p = SMOOTH_MAX_EXPONENT
    values = error_if(values, ~jnp.all(values > 0.0),
                      "HeavisideProjection(objective='max') takes the largest objective of the eroded, blueprint and "
                      "dilated designs as their p-norm, which needs positive values; shift the objective or use "
                      "objective='eroded' / 'dilated'.", DesignError)
    top = jnp.max(values)
    norm = top * jnp.sum((values / top) ** p) ** (1.0 / p)
    weights = (values / norm) ** (p - 1)
    return norm, jax.tree.map(lambda *g: sum(w * gi for w, gi in zip(weights, g)), *grads)


def make_objective(case: Case | OperatingConditions, method: str | AbstractSensitivity | None = None,
                   filter: DensityFilter | StackedFilter | dict[str, DensityFilter] | None = None,
                   projection: HeavisideProjection | None = None, **kwargs) -> Callable:
    """The objective of a case as a pure function `x -> (psi, grad psi)` for an optax loop.

    `psi` is the case's integral objective (REFERENCE_CASE §4) of the physical densities
    `x_phys = H x`, and `grad` its exact gradient with respect to the design `x`,
    `H^T grad psi(x_phys)` (see [`filtered_objective`][]). The function is pure and traceable, so
    it runs under `jax.jit` (compile it once, e.g. inside [`make_step`][]) and `jax.vmap`.

    **Arguments:**
    - `case`: e.g. `ffr_jax.cases.slider_crank(nx=12, ny=2, n_modes=3, t1=0.2)`, or
      [`OperatingConditions`][] (several crank speeds or loads as one batched solve).
    - `method`: sensitivity method of `ffr_jax.value_and_grad`: `"adjoint"`, `"autodiff"`,
      `"backsolve"`, `"direct"`, `"discrete-adjoint"`, `"fd"`, or a configured method object; default
      (with no `solver` either): the route [`choose_route`][ffr_jax.choose_route] picks for the case, as
      `ffr_jax.value_and_grad` does (the discrete adjoint of Rodas5P where an explicit solver would sit at
      its stability limit, e.g. the reference case; else the paper's adjoint with Dopri8).
    - `filter`: a [`DensityFilter`][], a dict of them by body (for a dict design), or `None`.
    - `projection`: a [`HeavisideProjection`][] after the filter, or `None`; with one the
      function is `fun(x, beta)`, `x_phys = P_beta(H x)` (a robust projection: the largest `psi` of its
      eroded, blueprint and dilated designs, or of the one design its `objective` names).
    - `**kwargs`: passed on to `ffr_jax.value_and_grad`, e.g. `rtol=1e-8, atol=1e-10`.

    **Returns:** `fun(x) -> (psi, grad)`, a scalar and an array shaped like `x`.

    **Example:**
    ```python
    fun = fj.make_objective(case, filter=fj.DensityFilter(case.design, 1.5), rtol=1e-6, atol=1e-12)
    psi, grad = jax.jit(fun)(case.initial_design(0.5))
    ```
    """
    base = case.case if isinstance(case, OperatingConditions) else case
    # The route resolved once here (method, solver, tolerances), so that every step runs the same settings and
    # the checkpoints' fingerprint names them; an unknown method name fails here, not at the first step.
    method, solver, rtol, atol, _ = _api._route(base, method, kwargs.pop("solver", None), kwargs.pop("rtol", None),
                                                kwargs.pop("atol", None))
    kwargs.update(solver=solver, rtol=rtol, atol=atol)
    if isinstance(case, OperatingConditions):
        def fun(x):
            return case.value_and_grad(x, method, **kwargs)[:2]
    else:
        def fun(x):
            return _api.value_and_grad(case, x, method, **kwargs)

    out = filtered_objective(fun, filter, projection)
    # What defines this objective, for the checkpoints of fj.optimize: a resume of a run made with
    # another case, mesh, filter, projection, method or tolerance is refused.
    out.fingerprint = tree_fingerprint((case, filter, projection, method, tuple(sorted(kwargs.items()))))
    out.projection = projection  # fj.optimize takes its default beta continuation when there is one
    out.design_size = (case.case if isinstance(case, OperatingConditions) else case).n_design  # checked by optimize
    # A case's objective runs its own compiled programs (fj.value_and_grad: compiled once, and kept between
    # processes for a concrete design), so make_step calls it as it is instead of tracing it into a program of
    # its own, which a later process would have to compile again.
    out.compiles_itself = not isinstance(case, OperatingConditions)
    return out
