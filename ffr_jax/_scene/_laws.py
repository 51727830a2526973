"""Prescribed motions as functions of time (rheonomic drivers)."""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np


class AbstractLaw(eqx.Module):
    """A scalar function of time `phi(t)`, smooth enough for accelerations (`C^2`)."""

    @abc.abstractmethod
    def __call__(self, t):
        """`phi(t)`."""

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times where the law changes pieces (for the step-size controller's `jump_ts`)."""
        return ()


class RampLaw(AbstractLaw):
    """Jerk-free run-up to a constant speed (paper eqs. 45–46).

    On `0 <= t <= t_ramp`, `phi` is the polynomial of degree at most 7 with
    `phi = phi' = phi'' = phi''' = 0` at `t = 0` and `phi = phi_ramp`, `phi' = omega`,
    `phi'' = phi''' = 0` at `t = t_ramp`; afterwards `phi = omega (t - t_ramp) + phi_ramp`.
    The reference case has `t_ramp = 2`, `phi_ramp = 12 pi`, `omega = 12 pi`; the `t^7`
    coefficient then vanishes. `breakpoints` tells the step-size controller where the law
    switches pieces.
    """

    coefficients: jnp.ndarray
    t_ramp: float = eqx.field(static=True)
    angle_at_ramp: jnp.ndarray
    speed: jnp.ndarray

    def __init__(self, t_ramp: float = 2.0, angle_at_ramp: float = 12 * np.pi, speed: float = 12 * np.pi):
        t_ramp = float(_scalar(t_ramp, "RampLaw t_ramp"))
        angle_at_ramp = float(_scalar(angle_at_ramp, "RampLaw angle_at_ramp"))
        speed = float(_scalar(speed, "RampLaw speed"))
        if t_ramp <= 0:
            raise ValueError(f"t_ramp must be positive, got {t_ramp}.")
        # Conditions on a_4..a_7 (a_0..a_3 vanish): phi, phi', phi'', phi''' at t_ramp.
        powers = np.arange(4, 8)
        rows = []
        for d in range(4):
            fall = np.array([np.prod(np.arange(p - d + 1, p + 1)) for p in powers], dtype=float)
            rows.append(fall * t_ramp ** (powers - d))
        rhs = np.array([angle_at_ramp, speed, 0.0, 0.0])
        a = np.linalg.solve(np.array(rows), rhs)
        self.coefficients = jnp.asarray(np.concatenate([np.zeros(4), a]))
        self.t_ramp = float(t_ramp)
        self.angle_at_ramp = jnp.asarray(float(angle_at_ramp))
        self.speed = jnp.asarray(float(speed))

    def __call__(self, t):
        tc = jnp.where(t <= self.t_ramp, t, self.t_ramp)
        poly = jnp.polyval(self.coefficients[::-1], tc)
        linear = self.speed * (t - self.t_ramp) + self.angle_at_ramp
        return jnp.where(t <= self.t_ramp, poly, linear)

    @property
    def breakpoints(self) -> tuple[float, ...]:
        return (self.t_ramp,)


class ConstantSpeedLaw(AbstractLaw):
    """`phi(t) = phi0 + omega t`."""

    initial: jnp.ndarray
    speed: jnp.ndarray

    def __init__(self, speed: float, initial: float = 0.0):
        self.initial = _scalar(initial, "ConstantSpeedLaw initial")
        self.speed = _scalar(speed, "ConstantSpeedLaw speed")

    def __call__(self, t):
        return self.initial + self.speed * t


class ConstantLaw(AbstractLaw):
    """`phi(t) = value` (an array: differentiable)."""

    value: jnp.ndarray

    def __init__(self, value: float):
        self.value = _scalar(value, "ConstantLaw value")

    def __call__(self, t):
        return self.value + 0.0 * t


class HarmonicLaw(AbstractLaw):
    """`phi(t) = offset + amplitude sin(2 pi frequency t + phase)` (arrays: differentiable)."""

    amplitude: jnp.ndarray
    frequency: jnp.ndarray
    phase: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, amplitude: float, frequency: float, phase: float = 0.0, offset: float = 0.0):
        self.amplitude = _scalar(amplitude, "HarmonicLaw amplitude")
        self.frequency = _scalar(frequency, "HarmonicLaw frequency")
        self.phase = _scalar(phase, "HarmonicLaw phase")
        self.offset = _scalar(offset, "HarmonicLaw offset")

    def __call__(self, t):
        return self.offset + self.amplitude * jnp.sin(2 * jnp.pi * self.frequency * t + self.phase)


def _scalar(value, name: str):
    """A finite float64 scalar array, or a `ValueError` that names the parameter."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}.") from None
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}.")
    return jnp.asarray(value)


def as_law(value) -> AbstractLaw:
    """A law from an [`AbstractLaw`][] or a number (a [`ConstantLaw`][])."""
    if isinstance(value, AbstractLaw):
        return value
    return ConstantLaw(value)
