"""The default route of a gradient: which sensitivity method, solver and tolerances `value_and_grad` takes.

An explicit solver integrating retained modes of angular frequency up to `omega_max` is stable only
for steps `h <= y_stab / omega_max`, with `y_stab` where the solver's stability region leaves the
imaginary axis (the modes are undamped: their eigenvalues `+-i omega` lie on it). Over a time span
`T` that is at least

    N_stab = omega_max T / y_stab

steps whatever the tolerance. Dopri8 (the explicit default) has `y_stab = 3.70`: its stability
function stays within `|R(iy)| <= 1 + 1e-7` up to `y = 3.70` and grows past 1 beyond (computed from
diffrax's tableau in `tests/test_route.py`); on the reference case (6 modes, 726 Hz, 3 s) `N_stab = 3,700`, and Dopri8
takes 4,790 steps at every rtol from 1e-6 to 1e-8 (benchmarks/RESULTS.md): it sits at its stability
limit, and its step count says nothing about the accuracy asked for.

Where `N_stab` exceeds [`STIFF_STEPS`][] the route is the stiff one: the discrete adjoint of the
linearly implicit Rodas5P ([`DiscreteAdjoint`][ffr_jax.DiscreteAdjoint]), not limited by
`omega_max`, at `rtol = 1e-6`, `atol = 2e-9`. There it is the fastest exact gradient measured at 6,
15 and 30 modes. Its documented accuracy is 1e-6 of the largest gradient entry: measured against
tight references on the reference case, 7.6e-8 / 1.8e-7 / 2.5e-7 at 6 / 15 / 30 modes (benchmarks/
RESULTS.md, "Default route"). The tolerances are chosen for that accuracy at the fewest steps: on
these cases the step count follows `atol` (the modal coordinates are small), not `rtol` (6 modes:
2,160 steps at 1e-7 / 1e-9, 1,950 at 1e-6 / 1e-9, 1,730 at 1e-6 / 2e-9, 1,281 at 1e-7 / 1e-8, the
last with an error of 7.4e-7: too close to 1e-6), and the backward pass costs a fixed time per step.
The other cases on this route, against the discrete adjoint at rtol 1e-9 / atol 1e-11: `four_bar()` 3.1e-7
(3.1e-7 at the earlier 1e-7 / 1e-9); `flexible_pendulum()` **1.1e-5** (5.1e-6 at 1e-7 / 1e-9), whose large
swing makes the error follow rtol: there pass `rtol=1e-8` (4.0e-7). Elsewhere the
route is the explicit one, the paper's: the adjoint variable method ([`Adjoint`][ffr_jax.Adjoint]) with
Dopri8 at the paper's tolerances (rtol 1e-10, atol 1e-12).
"""

import logging

import equinox as eqx
import jax
import numpy as np

from .._dynamics._problem import Problem
from .._scene._body_data import BodyData
from .._solver._rodas5p import Rodas5P
from ._adjoint import Adjoint
from ._base import AbstractSensitivity
from ._discrete_adjoint import DiscreteAdjoint

# Where Dopri8's stability function leaves the unit disc on the imaginary axis (module docstring).
DOPRI8_IMAGINARY_STABILITY = 3.7
# Stability-bound explicit steps above which the stiff route is taken. Measured on the reference case
# (benchmarks/RESULTS.md, "Default route"): at N_stab = 3,700 the stiff route is 2-3x faster at equal
# accuracy; a problem whose fastest mode needs fewer than 1,000 explicit steps is integrated in well
# under a second by Dopri8, whose accuracy then comes for free (an explicit step costs no Jacobian).
STIFF_STEPS = 1_000
# Chosen in the module docstring: the documented accuracy (1e-6 of the largest entry) with a margin of 4x or more
# at 6, 15 and 30 modes, in the fewest steps.
STIFF_RTOL, STIFF_ATOL = 1e-6, 2e-9
EXPLICIT_RTOL, EXPLICIT_ATOL = 1e-10, 1e-12

logger = logging.getLogger("ffr_jax")


class Route(eqx.Module):
    """The sensitivity method, solver and tolerances of a gradient, and why they were chosen.

    **Fields:**
    - `method`: the sensitivity method object; `solver`: the forward solver (`None`: the method's
      default, Dopri8); `rtol`, `atol`: forward tolerances.
    - `stiff`: whether the stiff route was taken; `omega_max`: the highest retained angular
      frequency of the scene's bodies [rad/s] (0 without modes, `nan` where unknown);
      `stability_steps`: `N_stab` (module docstring); `reason`: one line saying so.
    """

    method: AbstractSensitivity
    solver: object
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    stiff: bool = eqx.field(static=True)
    omega_max: float = eqx.field(static=True)
    stability_steps: float = eqx.field(static=True)
    reason: str = eqx.field(static=True)


def highest_frequency(problem: Problem) -> float:
    """The highest retained angular frequency `omega_max` [rad/s] of the problem's bodies, from their
    modal stiffness and mass (`K_q phi = omega^2 M_q phi`); 0 without modes, `nan` where the body
    data are traced (not known on the host)."""
    omega = 0.0
    for body in problem.scene.bodies:
        data = body.data
        if not isinstance(data, BodyData) or data.n_modes == 0:
            continue
        stiffness, mass = data.modal_stiffness, data.modal_mass
        if isinstance(stiffness, jax.core.Tracer) or isinstance(mass, jax.core.Tracer):
            return float("nan")
        eigenvalues = np.linalg.eigvals(np.linalg.solve(np.asarray(mass), np.asarray(stiffness)))
        omega = max(omega, float(np.sqrt(np.max(np.abs(eigenvalues)))))
    return omega


def choose_route(target) -> Route:
    """The route `ffr_jax.value_and_grad(target, x)` takes when no method is given (module docstring).

    **Arguments:**
    - `target`: a case (its template scene holds the body data of its nominal design) or a
      [`Problem`][ffr_jax.Problem].

    **Returns:** a [`Route`][ffr_jax.Route].

    **Example:**
    ```python
    import ffr_jax as fj
    route = fj.choose_route(fj.cases.slider_crank())
    print(route.reason)   # stiff: the discrete adjoint of Rodas5P ...
    ```
    """
    problem = target if isinstance(target, Problem) else target.problem
    span = problem.t1 - problem.t0
    omega = highest_frequency(problem)
    steps = omega * span / DOPRI8_IMAGINARY_STABILITY
    if steps > STIFF_STEPS:
        reason = (f"stiff route: the discrete adjoint of Rodas5P at rtol {STIFF_RTOL:g}, atol {STIFF_ATOL:g} (the "
                  f"highest retained frequency, {omega / (2 * np.pi):.4g} Hz over {span:g} s, would hold an "
                  f"explicit solver to at least {steps:,.0f} steps)")
        return Route(DiscreteAdjoint(), Rodas5P(), STIFF_RTOL, STIFF_ATOL, True, omega, steps, reason)
    if np.isnan(omega):
        why = "the body data are traced, so their frequencies are unknown here"
    elif omega == 0.0:
        why = "no retained modes"
    else:
        why = (f"the highest retained frequency, {omega / (2 * np.pi):.4g} Hz over {span:g} s, needs about "
               f"{steps:,.0f} explicit steps, at most {STIFF_STEPS:,}")
    reason = (f"explicit route: the paper's adjoint with Dopri8 at rtol {EXPLICIT_RTOL:g}, atol {EXPLICIT_ATOL:g} "
              f"({why})")
    return Route(Adjoint(), None, EXPLICIT_RTOL, EXPLICIT_ATOL, False, omega, steps, reason)
