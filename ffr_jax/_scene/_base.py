"""Abstract bases of scene elements."""

import abc

import equinox as eqx
import jax.numpy as jnp


class AbstractConstraint(eqx.Module):
    """A holonomic, possibly rheonomic, constraint `c(y_r, t, p) = 0` (paper eq. 9)."""

    @property
    @abc.abstractmethod
    def n_equations(self) -> int:
        """Number of scalar constraint equations (static)."""

    @abc.abstractmethod
    def residual(self, t, y_r, scene):
        """`c(y_r, t)`, shape `(n_equations,)`; `scene` gives access to body markers."""


class AbstractForce(eqx.Module):
    """A force element or effect: generalized forces `Q(t, y_r, z_r)` added to `h_a` (paper eq. 8)."""

    @abc.abstractmethod
    def generalized_force(self, t, y_r, z_r, scene):
        """Generalized force on all redundant coordinates, shape `(n_r,)`."""

    def potential_energy(self, t, y_r, scene):
        """Potential energy of a conservative element (zero for non-conservative ones)."""
        del t, y_r, scene
        return jnp.zeros(())
