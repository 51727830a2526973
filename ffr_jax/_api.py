"""Top-level functions: the objective of a case and its gradient by any sensitivity method."""

import diffrax

from ._case import FlexibleRodCase
from ._scene._scene import Scene
from ._sensitivity._adjoint import Adjoint
from ._sensitivity._autodiff import Autodiff
from ._sensitivity._backsolve import Backsolve
from ._sensitivity._base import AbstractSensitivity
from ._sensitivity._direct import Direct
from ._sensitivity._finite_differences import FiniteDifferences
from ._simulate import Trajectory, simulate
from ._typing import Design


METHODS = {
    "adjoint": Adjoint,
    "autodiff": Autodiff,
    "backsolve": Backsolve,
    "direct": Direct,
    "fd": FiniteDifferences,
}


def sensitivity_method(method: str | AbstractSensitivity) -> AbstractSensitivity:
    """Map a method name (`"adjoint"`, `"autodiff"`, `"backsolve"`, `"direct"`, `"fd"`) to its object."""
    if isinstance(method, AbstractSensitivity):
        return method
    if method not in METHODS:
        raise ValueError(f"Unknown sensitivity method {method!r}; choose one of {sorted(METHODS)} "
                         "or pass an AbstractSensitivity instance (e.g. ffr_jax.Adjoint(rtol=1e-9)).")
    return METHODS[method]()


def simulate_case(case: FlexibleRodCase, x: Design, *, rtol: float = 1e-10, atol: float = 1e-12,
                  solver: diffrax.AbstractSolver | None = None, ts=None, dense: bool = False,
                  max_steps: int = 1_000_000, adjoint: diffrax.AbstractAdjoint | None = None) -> Trajectory:
    """Simulate a case for design `x` with its objective integrated along (see [`simulate`][])."""
    return simulate(
        case.model, case.scene(x), case.t0, case.t1, case.y_r0, case.z_r0,
        integrand=case.integrand, solver=solver, rtol=rtol, atol=atol, ts=ts, dense=dense,
        max_steps=max_steps, adjoint=adjoint, jump_ts=case.jump_ts,
    )


def objective(case: FlexibleRodCase, x: Design, *, rtol: float = 1e-10, atol: float = 1e-12,
              solver: diffrax.AbstractSolver | None = None, max_steps: int = 1_000_000):
    """`psi(x) = int_{t0}^{t1} F(t, y_r, p(x)) dt` of a case (REFERENCE_CASE §4: the integral compliance).

    **Arguments:**
    - `case`: e.g. `ffr_jax.cases.slider_crank()`; `x`: `(n_design,)` densities in `[x_min, 1]`.
    - `rtol`, `atol`: forward tolerances (the paper's 1e-10 / 1e-12 by default).
    - `solver`: diffrax solver (default `Dopri8()`, see [`simulate`][]).

    **Returns:** scalar `psi`.
    """
    return simulate_case(case, x, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps).psi


def value_and_grad(case: FlexibleRodCase, x: Design, method: str | AbstractSensitivity = "adjoint", *,
                   rtol: float = 1e-10, atol: float = 1e-12, solver: diffrax.AbstractSolver | None = None,
                   max_steps: int = 200_000):
    """`(psi(x), grad psi(x))` of a case by the chosen sensitivity method.

    **Arguments:**
    - `case`: e.g. `ffr_jax.cases.slider_crank()`; `x`: `(n_design,)` densities in `[x_min, 1]`.
    - `method`: `"adjoint"` (the paper's adjoint variable method, default), `"autodiff"`
      (`jax.grad` through diffrax), `"backsolve"` (diffrax `BacksolveAdjoint`), `"direct"`
      (forward sensitivities), `"fd"` (central differences), or a configured method object such
      as `ffr_jax.Adjoint(rtol=1e-9, atol=1e-11)` or `ffr_jax.FiniteDifferences(step=1e-4)`.
    - `rtol`, `atol`: forward tolerances (the paper's 1e-10 / 1e-12 by default).
    - `solver`: diffrax solver of the forward solve (default `Dopri8()`); the adjoint and backsolve
      methods integrate backward with the same solver when one is given, else with `Dopri8()`.
    - `max_steps`: step budget of each solve. The adjoint method keeps the dense output of its
      forward and backward solves for that many steps (about 1 KB per step each; the reference
      case needs about 8,000 forward and 13,000 backward steps), so the default is 200,000 rather
      than the 1,000,000 of [`objective`][]: raise it for long horizons or low-order solvers.

    **Returns:** `(psi, grad)`, a scalar and an array shaped like `x`. Works under `jax.jit`
    and `jax.vmap` (a batch of designs).

    **Example:**
    ```python
    import ffr_jax as fj
    case = fj.cases.slider_crank()
    psi, grad = fj.value_and_grad(case, case.initial_design(0.5))
    ```
    """
    x = case.design.check(x)
    return sensitivity_method(method).value_and_grad_design(
        case, x, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps
    )


def value_and_grad_scene(case: FlexibleRodCase, scene: Scene, method: str | AbstractSensitivity = "adjoint", *,
                         rtol: float = 1e-10, atol: float = 1e-12, solver: diffrax.AbstractSolver | None = None,
                         max_steps: int = 200_000):
    """`(psi, dpsi/dp)` with respect to every array of the scene (body data, spring constants, crank
    radius, law coefficients, ...): a pytree like `scene`, `None` where a leaf is not a float array.
    """
    return sensitivity_method(method).value_and_grad_scene(
        case, scene, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps
    )
