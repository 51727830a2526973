"""Abstract integrand of an integral objective."""

import abc

import equinox as eqx


class AbstractIntegrand(eqx.Module):
    """The integrand `F(t, y_r, p)` of `psi = int_{t0}^{t1} F dt` (paper eq. 20).

    `F` may depend on the redundant positions and on any array of the scene `p`; its partial
    derivatives are taken by JAX (`R1`, `R2` of paper eq. 25).
    """

    @abc.abstractmethod
    def __call__(self, t, y_r, scene):
        """Scalar `F(t, y_r, p)`."""
