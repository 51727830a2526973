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

    **Robust formulation (a minimum length scale).** Given `eta_eroded > eta > eta_dilated`, one
    filtered field makes three designs, `P_beta` at the three thresholds (paper Sect. 4): the
    *eroded* design (`eta_eroded`: every member thinner by the same offset), the *blueprint*
    (`eta`) and the *dilated* one (`eta_dilated`: thicker); `designs`
    returns them, eroded `<=` blueprint `<=` dilated element by element. `__call__` returns the
    blueprint: it is the design that [`physical_densities`][ffr_jax.physical_densities], the volume,
    mass and frequency constraints, [`grey_share`][ffr_jax.grey_share] and the plots see, and the
    design a run reports. The objective of [`make_objective`][ffr_jax.make_objective] (and
    [`filtered_objective`][ffr_jax.filtered_objective]) is evaluated on the design `objective` names:

    - `"max"` (default): the paper's min-max, `max(psi(eroded), psi(blueprint), psi(dilated))`,
      taken as the p-norm of the three values (`p = 16`, within 7 % of the largest, exact gradient;
      the values must be positive, as the integral objectives of this package are). Three dynamics
      solves per step. A feature counts only if the design performs with it eroded *and* dilated: a
      member narrower than about the filter's diameter vanishes from the eroded design, a thin slot
      closes in the dilated one, so neither is worth keeping. That is the minimum size of members
      and holes that the plain projection lacks (issue 30: struts narrower than the filter stayed
      grey at `u ~ eta`). Where one design dominates the p-norm the others weigh little: on the
      slider–crank rod the dilated design is the worst, and a member thin in the blueprint and
      absent from the eroded design costs little (5 % of the 800 x 48 rod's solid lay in no
      5 mm square, against 0.5 % with `"eroded"`).
    - `"eroded"`, `"blueprint"`, `"dilated"`: that one design, one solve per step (the paper's cheap
      variant). It is the min-max only where the design named is the worst case, as the eroded one
      is for a stiffness-dominated objective (a static compliance: `psi(eroded) >= psi(blueprint) >=
      psi(dilated)`). Not for the slider–crank rod's inertia-loaded `psi`: there the eroded design is
      the *best* (less mass, less inertia load), and optimising it fills the blueprint with material
      the objective does not see (psi of the blueprint 0.0280 against the min-max's 0.0178 at
      400 x 24); optimising the dilated design (the worst there) leaves a blueprint too thin to run
      (`benchmarks/RESULTS.md`, "Time to a design"). Check the order on the final designs with
      `designs`.

    **Arguments:**
    - `eta`: threshold in `(0, 1)` (0.5: densities above the middle go solid); the blueprint's.
    - `x_min`: the lower bound of the densities (`case.material.x_min`).
    - `eta_eroded`, `eta_dilated`: the robust formulation's thresholds, both or neither, with
      `0 < eta_dilated < eta < eta_eroded < 1` (Wang, Lazarov, Sigmund use 0.3 / 0.5 / 0.7; the
      wider apart, the larger the minimum member size). `None` (default): the plain projection.
    - `objective`: with the robust formulation, the design(s) the objective is evaluated on:
      `"max"` (default), `"eroded"`, `"blueprint"` or `"dilated"` (see above).

    **Example:**
    ```python
    projection = fj.HeavisideProjection(eta=0.5, x_min=case.material.x_min)
    x_phys = projection(filt(x), beta=8.0)
    robust = fj.HeavisideProjection(0.5, x_min=case.material.x_min, eta_eroded=0.7, eta_dilated=0.3)
    eroded, blueprint, dilated = robust.designs(filt(x), beta=8.0)
    ```

    !!! cite "Reference"
        F. Wang, B. S. Lazarov, O. Sigmund, "On projection methods, convergence and robust
        formulations in topology optimization", Struct. Multidiscip. Optim. 43 (2011) 767–784.
    """

    eta: float = eqx.field(static=True)
    x_min: float = eqx.field(static=True)
    eta_eroded: float | None = eqx.field(static=True)
    eta_dilated: float | None = eqx.field(static=True)
    objective: str = eqx.field(static=True)

    def __init__(self, eta: float = 0.5, *, x_min: float = 0.01, eta_eroded: float | None = None,
                 eta_dilated: float | None = None, objective: str = "max"):
        if not 0.0 < eta < 1.0:
            raise ValueError(f"The projection threshold eta must lie in (0, 1), got {eta}.")
        if not 0.0 < x_min < 1.0:
            raise ValueError(f"x_min must lie in (0, 1), got {x_min}.")
        if (eta_eroded is None) != (eta_dilated is None):
            raise ValueError("The robust formulation needs both thresholds, eta_eroded and eta_dilated (e.g. 0.7 and "
                             f"0.3 around eta = 0.5), or neither; got eta_eroded={eta_eroded}, "
                             f"eta_dilated={eta_dilated}.")
        if eta_eroded is not None and not 0.0 < eta_dilated < eta < eta_eroded < 1.0:
            raise ValueError(f"The robust formulation needs 0 < eta_dilated < eta < eta_eroded < 1 (the eroded design "
                             f"thinner, the dilated one thicker than the blueprint), got eta_dilated={eta_dilated}, "
                             f"eta={eta}, eta_eroded={eta_eroded}; e.g. 0.3, 0.5, 0.7.")
        if objective not in ROBUST_OBJECTIVES:
            raise ValueError(f"objective must be one of {ROBUST_OBJECTIVES} (the design the objective is evaluated "
                             f"on, or 'max': the largest over the three), got {objective!r}.")
        if objective != "max" and eta_eroded is None:
            raise ValueError(f"objective={objective!r} needs the robust formulation: give eta_eroded and eta_dilated.")
        self.objective = objective
        self.eta = float(eta)
        self.x_min = float(x_min)
        self.eta_eroded = None if eta_eroded is None else float(eta_eroded)
        self.eta_dilated = None if eta_dilated is None else float(eta_dilated)

    @property
    def robust(self) -> bool:
        """Whether this is the robust formulation (eroded, blueprint and dilated designs)."""
        return self.eta_eroded is not None

    def __call__(self, x_filtered: Design, beta: Scalar | float) -> Design:
        """Physical densities `x_min + (1 - x_min) P_beta(u)` of filtered densities `(n_design,)` (the
        blueprint, at `eta`)."""
        return self._project(x_filtered, beta, self.eta)

    def objective_design(self, x_filtered: Design, beta: Scalar | float) -> Design:
        """The design the objective is evaluated on: in the robust formulation the one `objective` names
        (`"eroded"`, `"blueprint"` or `"dilated"`), else the blueprint `__call__` returns. `(n_design,)`."""
        if not self.robust:
            return self(x_filtered, beta)
        if self.objective == "max":
            raise ValueError("objective='max' evaluates the objective on all three designs: use designs().")
        eta = {"eroded": self.eta_eroded, "blueprint": self.eta, "dilated": self.eta_dilated}[self.objective]
        return self._project(x_filtered, beta, eta)

    def designs(self, x_filtered: Design, beta: Scalar | float) -> tuple[Design, Design, Design]:
        """The robust formulation's eroded, blueprint and dilated designs of one filtered field.

        **Arguments:** `x_filtered`: `(n_design,)` filtered densities; `beta`: the sharpness.

        **Returns:** `(eroded, blueprint, dilated)`, each `(n_design,)`, ordered element by element
        (`P_beta` at a higher threshold is lower).
        """
        if not self.robust:
            raise ValueError("designs() needs the robust formulation: HeavisideProjection(eta, x_min=..., "
                             "eta_eroded=..., eta_dilated=...).")
        return tuple(self._project(x_filtered, beta, eta) for eta in (self.eta_eroded, self.eta, self.eta_dilated))

    def _project(self, x_filtered, beta, eta):
        if not is_traced(beta):
            _check_beta(beta, "HeavisideProjection(...)(x, beta)")
        beta = jnp.asarray(beta, dtype=x_filtered.dtype)
        # A traced beta (a schedule's value inside a compiled step): inf or nan would make P_beta NaN.
        beta = error_if(beta, ~(beta > 0.0) | ~jnp.isfinite(beta), BETA_MESSAGE, DesignError)
        u = (x_filtered - self.x_min) / (1.0 - self.x_min)
        a = jnp.tanh(beta * eta)
        p = (a + jnp.tanh(beta * (u - eta))) / (a + jnp.tanh(beta * (1.0 - eta)))
        # Round-off in H x may leave u a hair outside [0, 1]; the bounds are exact.
        return jnp.clip(self.x_min + (1.0 - self.x_min) * p, self.x_min, 1.0)


# The designs the robust formulation's objective may be evaluated on, and "max": the largest over the three.
ROBUST_OBJECTIVES = ("eroded", "blueprint", "dilated", "max")

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
