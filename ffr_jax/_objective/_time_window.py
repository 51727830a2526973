"""The time average of an objective term over a window of the motion."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractIntegrand


class TimeWindow(AbstractIntegrand):
    """`F_w(t) = F(t) / (t_b - t_a)` for `t_a <= t <= t_b`, `0` otherwise: as the integrand of an objective,
    `psi = 1 / (t_b - t_a) int_{t_a}^{t_b} F dt` is the time average of the term `F` over the window.

    Use it to leave a run-up out of the objective: e.g. the compliance averaged over whole crank turns at steady
    speed, after the transient of the start has died out, is a periodic quantity that does not depend on where in an
    oscillation of the elastic modes the motion ends. The integrand jumps at `t_a` and `t_b`: give both to the
    [`Problem`][]'s `jump_ts` (its `breakpoints`) so that the step-size controller lands on them.

    **Arguments:**
    - `term`: the [`AbstractIntegrand`][] averaged (e.g. [`Compliance`][]).
    - `t_start`, `t_end`: the window `[t_a, t_b]` in s (static; `t_end > t_start`).
    """

    term: AbstractIntegrand
    t_start: float = eqx.field(static=True)
    t_end: float = eqx.field(static=True)

    def __init__(self, term, t_start: float, t_end: float):
        if not isinstance(term, AbstractIntegrand):
            raise ValueError(f"TimeWindow averages an objective term (e.g. ffr_jax.Compliance(body=0)), got "
                             f"{type(term).__name__}.")
        t_start, t_end = float(t_start), float(t_end)
        if not t_end > t_start:
            raise ValueError(f"TimeWindow needs t_end > t_start (the window in s), got [{t_start}, {t_end}].")
        self.term, self.t_start, self.t_end = term, t_start, t_end

    @property
    def breakpoints(self) -> tuple[float, float]:
        """`(t_a, t_b)`: where the integrand jumps (for the problem's `jump_ts`)."""
        return (self.t_start, self.t_end)

    def __call__(self, t, y_r, z_r, scene):
        inside = (t >= self.t_start) & (t <= self.t_end)
        value = self.term(t, y_r, z_r, scene)
        return jnp.where(inside, value / (self.t_end - self.t_start), jnp.zeros_like(value))
