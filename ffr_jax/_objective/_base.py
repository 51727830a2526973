"""Abstract scalar term of an objective (an integrand `F` or a terminal term `G`) and the algebra of terms:
sums and weighted terms."""

import abc

import equinox as eqx
import jax.numpy as jnp


class AbstractIntegrand(eqx.Module):
    """A scalar function `F(t, y_r, z_r, p)` of the time, the redundant positions and velocities
    and the parameters `p` (the scene), used as the integrand of `psi = int_{t0}^{t1} F dt`
    (paper eq. 20) or as the terminal term `G(t1, y_r, z_r, p)` of an [`Objective`][].

    Its partial derivatives (`R1`, `R2` of paper eq. 25, and the velocity and terminal terms of
    the extended adjoint, see [`Adjoint`][]) are taken by JAX. Terms add (`a + b`) and scale by a
    number or a scalar array (`2.0 * a`; an array weight is a parameter that can be differentiated
    and changed without recompiling).
    """

    @abc.abstractmethod
    def __call__(self, t, y_r, z_r, scene):
        """Scalar `F(t, y_r, z_r, p)`."""

    def __add__(self, other: "AbstractIntegrand") -> "AbstractIntegrand":
        if not isinstance(other, AbstractIntegrand):
            return NotImplemented
        return Sum((self, other))

    def __mul__(self, weight) -> "AbstractIntegrand":
        if isinstance(weight, AbstractIntegrand):
            return NotImplemented
        return Scaled(self, weight)

    __rmul__ = __mul__


def scalar(value, name: str):
    """`value` as a float64 scalar array, or a `ValueError` naming the term when it is not one number."""
    value = jnp.asarray(value, dtype=float)
    if value.shape != ():
        raise ValueError(f"{name} must be one number, got an array of shape {value.shape}.")
    return value



class Sum(AbstractIntegrand):
    """`F = F_1 + F_2 + ...` (written `a + b`)."""

    terms: tuple[AbstractIntegrand, ...]

    def __check_init__(self):
        if not self.terms or not all(isinstance(t, AbstractIntegrand) for t in self.terms):
            raise ValueError("Sum needs one or more objective terms (AbstractIntegrand instances).")

    def __call__(self, t, y_r, z_r, scene):
        total = jnp.zeros((), y_r.dtype)
        for term in self.terms:
            total = total + term(t, y_r, z_r, scene)
        return total


class Scaled(AbstractIntegrand):
    """`F = w F_1` (written `w * a`); the weight `w` is a scalar array, so it can be differentiated
    and changed without recompiling."""

    term: AbstractIntegrand
    weight: jnp.ndarray

    def __init__(self, term: AbstractIntegrand, weight):
        if not isinstance(term, AbstractIntegrand):
            raise ValueError(f"Scaled needs an objective term, got {type(term).__name__}.")
        self.term = term
        self.weight = scalar(weight, "The weight of an objective term")

    def __call__(self, t, y_r, z_r, scene):
        return self.weight * self.term(t, y_r, z_r, scene)
