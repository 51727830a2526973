"""The spin-up manoeuvre of Kane, Ryan and Banerjee (1987)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._laws import AbstractLaw, _scalar


class SpinUpLaw(AbstractLaw):
    """A smooth spin-up from rest to the speed `Omega_s` in the time `T`, then constant speed.

    `phi' = Omega_s / T (t - T / (2 pi) sin(2 pi t / T))` for `t < T`, `Omega_s` afterwards, so

    `phi = Omega_s / T (t^2 / 2 + (T / (2 pi))^2 (cos(2 pi t / T) - 1))` for `t < T`, `Omega_s (t - T / 2)` afterwards;

    `phi''` starts and ends at zero (`C^2`; the third derivative jumps at `T`, a breakpoint).

    **Arguments:** `speed`: `Omega_s` (rad/s); `t_spin`: `T` (s, positive).

    !!! cite "Reference"
        T. R. Kane, R. R. Ryan, A. K. Banerjee, "Dynamics of a cantilever beam attached to a moving base",
        J. Guidance, Control, and Dynamics 10 (1987) 139–151.
    """

    speed: jnp.ndarray
    t_spin: float = eqx.field(static=True)

    def __init__(self, speed: float, t_spin: float):
        t_spin = float(_scalar(t_spin, "SpinUpLaw t_spin"))
        if not t_spin > 0:
            raise ValueError(f"SpinUpLaw t_spin must be positive, got {t_spin}.")
        self.speed = jnp.asarray(float(_scalar(speed, "SpinUpLaw speed")))
        self.t_spin = t_spin

    def __call__(self, t):
        period = self.t_spin
        c = 2.0 * np.pi / period
        tc = jnp.minimum(t, period)
        ramp = self.speed / period * (0.5 * tc * tc + (jnp.cos(c * tc) - 1.0) / c**2)
        return jnp.where(t < period, ramp, self.speed * (t - 0.5 * period))

    @property
    def breakpoints(self) -> tuple[float, ...]:
        return (self.t_spin,)
