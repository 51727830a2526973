"""Sums and weighted terms of an objective."""

import equinox as eqx
import jax.numpy as jnp

from ._base import AbstractIntegrand, scalar


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
