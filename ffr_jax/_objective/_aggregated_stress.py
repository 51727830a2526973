"""The aggregated (p-norm) stress of a designed body over its elements and the motion, with its design gradient."""

import equinox as eqx
import jax.numpy as jnp

from .. import _api
from .._compiled import Program
from .._dynamics._case import Case
from .._errors import clean_errors
from .._sensitivity._finite_differences import FiniteDifferences
from .._outputs._peak_stress import designed_body_index
from .._outputs._relaxed_stresses import relaxed_stress_modes
from ._objective import Objective
from ._stress_measure import StressMeasure, check_stress_options


def stress_problem(case: Case, x, limit, power, relaxation):
    """The case's problem at design `x` with the [`StressMeasure`][] of its designed body as the objective."""
    index = case.problem.scene.body_index(case.design_map.names[0])
    measure = StressMeasure(relaxed_stress_modes(case.design, x, relaxation), index, limit, power)
    return eqx.tree_at(lambda p: p.objective, case.problem_for(x), Objective(integrand=measure))


def _aggregated_fn(case, x, limit, power, relaxation, method, rtol, atol, solver, max_steps):
    problem, pullback = eqx.filter_vjp(lambda x: stress_problem(case, x, limit, power, relaxation), x)
    psi, g_problem = method.value_and_grad_problem(problem, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps)
    (g_psi,) = pullback(g_problem)
    span = case.problem.t1 - case.problem.t0
    sigma = limit * (psi / span) ** (1.0 / power)
    # d sigma / d psi = sigma / (P psi); psi > 0 wherever the body deforms at all.
    return sigma, (sigma / (power * psi)) * g_psi


_aggregated = Program(_aggregated_fn, "the aggregated stress and its design gradient")


@clean_errors
def aggregated_stress(case, x, limit, *, power=8.0, relaxation=0.5,
                      method="adjoint", rtol: float = 1e-10, atol: float = 1e-12, solver=None,
                      max_steps: int = 200_000):
    """`(sigma_PN, d sigma_PN / dx)`: the `P`-norm of the relaxed von Mises stress of the case's designed body
    over its Gauss points and the motion, and its exact design gradient.

    `sigma_PN = sigma_lim ((1/(t1 - t0)) int_{t0}^{t1} sum_{e,g} (sigma_vm_hat_eg / sigma_lim)^P dt)^(1/P)`

    with the qp-relaxed stresses `sigma_hat = x_e^s E0 D B_g Phi q(t)` ([`relaxed_stress_modes`][]),
    so that vanishing elements do not dominate. The sum over points makes `sigma_PN` an upper
    bound of the peak over the points at each instant, the time mean a lower bound over time; both
    approach the peak as `P` grows (benchmarks/RESULTS.md gives the ratio peak / `sigma_PN` at the
    optimum of the stress-limited rod). `sigma_PN <= sigma_lim` is the stress constraint of
    [`stress_constraint`][] (an MMA constraint).

    The gradient: `psi = int F dt` of a [`StressMeasure`][] is differentiated with respect to the
    scene and to the stress modes by `method` (the paper's adjoint by default: `R1` of eq. 25 holds
    the stress term), and both are pulled back to `x` by one VJP of `x -> (p(x), sigma_hat_k(x))`.

    The measure is normalised by `limit`: give a limit of the size of the stresses (as a binding
    constraint has). A limit far above them makes `psi` tiny against the adjoint's absolute
    tolerances, and the adjoint gradient loses its digits (on the family rod with stresses of
    5e3 Pa, a limit of 1e6 Pa gave a gradient 2.4x off autodiff; at 5e3 Pa they agree to 2e-8).

    **Arguments:**
    - `case`: a case with one designed body; `x`: its design.
    - `limit`: `sigma_lim` > 0 in Pa (the normalisation; the constraint's bound).
    - `power`: `P >= 2` (default 8); `relaxation`: `s >= 0` (default 0.5).
    - `method`: `"adjoint"` (default), `"autodiff"`, `"backsolve"`, `"direct"`, `"discrete-adjoint"` or a
      method object; `rtol`, `atol`, `solver`, `max_steps`: of the forward solve (the paper's 1e-10 / 1e-12).

    **Returns:** `(sigma_PN, grad)`, a scalar in Pa and an array shaped like `x`.
    """
    limit, power = check_stress_options(limit, power, relaxation, "ffr_jax.aggregated_stress")
    designed_body_index(case, "ffr_jax.aggregated_stress")
    method = _api.sensitivity_method(method)
    if isinstance(method, FiniteDifferences):
        raise ValueError("ffr_jax.aggregated_stress: finite differences difference the design itself; difference "
                         "aggregated_stress(case, x +- h v, ...)[0] instead.")
    _api._check_options("ffr_jax.aggregated_stress", rtol, atol, max_steps)
    x = _api._design(case, x, "ffr_jax.aggregated_stress")
    # The limit as an array: an input of the compiled program, so that another limit does not compile it again.
    return _aggregated(case, x, jnp.asarray(limit, dtype=float), power, float(relaxation), method, rtol, atol, solver,
                       max_steps)

