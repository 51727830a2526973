"""A stress limit on a designed body as an inequality constraint of the optimizers (MMA)."""

from .._objective._aggregated_stress import aggregated_stress
from .._objective._stress_measure import check_stress_options
from .._outputs._peak_stress import designed_body_index
from ._function_constraint import FunctionConstraint
from ._objective import filtered_objective


def stress_constraint(case, limit, *, filter=None, projection=None, power=8.0,
                      relaxation=0.5, method="adjoint", name: str = "stress", **kwargs) -> FunctionConstraint:
    """`sigma_PN(x_phys) <= limit`: the aggregated relaxed von Mises stress of the case's designed body
    ([`aggregated_stress`][]) as a [`FunctionConstraint`][] for [`MMA`][], normalised
    `g = sigma_PN / limit - 1`.

    `sigma_PN` is a `P`-norm over the Gauss points and the motion: it does not equal the peak stress
    (it lies above the peak over the points and below it over time); where the peak itself must stay
    below a value, lower `limit` by the ratio peak / `sigma_PN` measured at a design near the optimum
    (benchmarks/RESULTS.md, "Stress-limited rod"). A limit no design can meet shows at the end of
    [`optimize`][] as a `ConstraintViolationWarning` naming this constraint (`result.feasible` False).

    **Arguments:**
    - `case`: a case with one designed body; `limit`: the stress limit in Pa (> 0).
    - `filter`, `projection`: the same density filter (and projection) as the objective's, so that
      the constraint sees the same physical densities.
    - `power`, `relaxation`, `method`, `**kwargs` (`rtol`, `atol`, `solver`, `max_steps`): of [`aggregated_stress`][].
    - `name`: the label in logs and plots.

    **Returns:** a [`FunctionConstraint`][] (`fun(x)` or, with a projection, `fun(x, beta)`).

    **Example:**
    ```python
    filt = fj.DensityFilter(case.design, 1.5)
    constraints = [fj.VolumeConstraint(0.5, filter=filt), fj.stress_constraint(case, 2e6, filter=filt)]
    result = fj.optimize(fj.make_objective(case, filter=filt), x0, fj.MMA(), constraints, iterations=30)
    ```
    """
    limit, power = check_stress_options(limit, power, relaxation, "ffr_jax.stress_constraint")
    designed_body_index(case, "ffr_jax.stress_constraint")

    def value(x_phys):
        return aggregated_stress(case, x_phys, limit, power=power, relaxation=relaxation, method=method, **kwargs)

    return FunctionConstraint(filtered_objective(value, filter, projection), limit, name=name)
