"""Heaviside (threshold) projection of the filtered densities, and its continuation in `beta`."""

import math
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp

from .._checks import is_traced
from .._errors import DesignError, error_if
from .._typing import Design, Scalar


class HeavisideProjection(eqx.Module):
    """The smoothed Heaviside projection `x_phys = P_beta(x_filtered)` (Wang, Lazarov, Sigmund 2011).

    On the normalised density `u = (x_filtered - x_min) / (1 - x_min)` in `[0, 1]`,

        P_beta(u) = (tanh(beta eta) + tanh(beta (u - eta))) / (tanh(beta eta) + tanh(beta (1 - eta))),

    and `x_phys = x_min + (1 - x_min) P_beta(u)`. `P_beta` is smooth and increasing, maps
    `0 -> 0`, `1 -> 1` and `eta -> eta`-ish, tends to the identity as `beta -> 0` and to a step at
    `eta` as `beta -> inf`. Densities pushed to either side of `eta` therefore become 0 or 1 as
    `beta` grows (continuation, [`beta_continuation`][]), while the filter below it keeps its
    minimum length scale. The map acts element by element, so its derivative is diagonal and
    `grad_x psi = H^T (P_beta'(H x) grad_phys psi)` (taken by `jax.vjp` in
    [`filtered_objective`][], applied to value and gradient alike). The physical densities stay in
    `[x_min, 1]`, which the SIMP law and `RodDesign.check` need.

    `beta` is an argument of `__call__`, not a field, so a loop can raise it without recompiling.

    **Arguments:**
    - `eta`: threshold in `(0, 1)` (0.5: densities above the middle go solid).
    - `x_min`: the lower bound of the densities (`case.material.x_min`).

    **Example:**
    ```python
    projection = fj.HeavisideProjection(eta=0.5, x_min=case.material.x_min)
    x_phys = projection(filt(x), beta=8.0)
    ```

    !!! cite "Reference"
        F. Wang, B. S. Lazarov, O. Sigmund, "On projection methods, convergence and robust
        formulations in topology optimization", Struct. Multidiscip. Optim. 43 (2011) 767–784.
    """

    eta: float = eqx.field(static=True)
    x_min: float = eqx.field(static=True)

    def __init__(self, eta: float = 0.5, *, x_min: float = 0.01):
        if not 0.0 < eta < 1.0:
            raise ValueError(f"The projection threshold eta must lie in (0, 1), got {eta}.")
        if not 0.0 < x_min < 1.0:
            raise ValueError(f"x_min must lie in (0, 1), got {x_min}.")
        self.eta = float(eta)
        self.x_min = float(x_min)

    def __call__(self, x_filtered: Design, beta: Scalar | float) -> Design:
        """Physical densities `x_min + (1 - x_min) P_beta(u)` of filtered densities `(n_design,)`."""
        if not is_traced(beta):
            _check_beta(beta, "HeavisideProjection(...)(x, beta)")
        beta = jnp.asarray(beta, dtype=x_filtered.dtype)
        # A traced beta (a schedule's value inside a compiled step): inf or nan would make P_beta NaN.
        beta = error_if(beta, ~(beta > 0.0) | ~jnp.isfinite(beta), BETA_MESSAGE, DesignError)
        u = (x_filtered - self.x_min) / (1.0 - self.x_min)
        a = jnp.tanh(beta * self.eta)
        p = (a + jnp.tanh(beta * (u - self.eta))) / (a + jnp.tanh(beta * (1.0 - self.eta)))
        # Round-off in H x may leave u a hair outside [0, 1]; the bounds are exact.
        return jnp.clip(self.x_min + (1.0 - self.x_min) * p, self.x_min, 1.0)


BETA_MESSAGE = ("The projection sharpness beta must be a finite positive number (at beta = inf the projection "
                "P_beta is NaN, tanh(inf) / tanh(inf)); continuation schedules stop at a finite beta_max such as 32.")


def _check_beta(beta, where: str) -> float:
    """A concrete `beta`: a finite number `> 0`, or a `ValueError` naming `where`."""
    try:
        value = float(beta)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: beta must be a number, got {beta!r}.") from None
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{where}: beta = {value}. {BETA_MESSAGE}")
    return value


# The default continuation of fj.optimize (a projected objective without `beta`) and of `ffr-jax optimize
# --optimizer mma`: beta 1, 2, 4, 8, 16, 32 from step 50 on. At beta = 32 only filtered densities within
# atanh(0.8) / 32 = 0.034 of eta project into the grey band 0.1 < x_phys < 0.9.
DEFAULT_BETA_START, DEFAULT_BETA_MAX, DEFAULT_BETA_EVERY = 1.0, 32.0, 10


def beta_continuation(start: float = DEFAULT_BETA_START, stop: float = DEFAULT_BETA_MAX,
                      every: int = DEFAULT_BETA_EVERY, factor: float = 2.0) -> Callable[[int], float]:
    """A continuation schedule for the projection sharpness: `beta_k = min(stop, start factor^floor(k / every))`.

    A pure function of the iteration `k`, so a resumed run uses the same `beta_k` as an
    uninterrupted one. Its defaults (1, 2, 4, ..., 32, doubled every 10 steps) are what
    [`optimize`][] takes for a projected objective given no `beta`, and what `ffr-jax optimize
    --optimizer mma` uses (`--projection-beta 1 --beta-max 32 --beta-every 10`).

    **Arguments:**
    - `start`: `beta_0 > 0` (default 1); `stop`: the largest `beta` (`>= start`, default 32).
    - `every`: iterations between raises (`>= 1`, default 10); `factor`: multiplier per raise (`> 1`).

    **Returns:** `schedule(k) -> beta_k` (a Python float).

    **Example:**
    ```python
    schedule = fj.beta_continuation(1.0, 32.0, every=20)   # 1, 2, 4, ..., 32 from step 100 on
    ```
    """
    if not (math.isfinite(float(start)) and math.isfinite(float(stop)) and math.isfinite(float(factor))):
        raise ValueError(f"beta continuation needs finite start, stop and factor, got start={start}, stop={stop}, "
                         f"factor={factor}. {BETA_MESSAGE}")
    if not 0.0 < start <= stop:
        raise ValueError(f"beta continuation needs 0 < start <= stop, got start={start}, stop={stop}.")
    if every < 1:
        raise ValueError(f"beta continuation: every must be >= 1 iteration, got {every}.")
    if not factor > 1.0:
        raise ValueError(f"beta continuation: factor must be > 1, got {factor}.")

    def schedule(k: int) -> float:
        return float(min(stop, start * factor ** (k // every)))

    return schedule
