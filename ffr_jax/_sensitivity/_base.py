"""Abstract base of the sensitivity methods."""

import abc

import diffrax
import equinox as eqx

from .._case import FlexibleRodCase
from .._scene._scene import Scene


class AbstractSensitivity(eqx.Module):
    """A way to compute `psi` and `d psi / d p` for the parameter pytree `p` (a [`Scene`][]).

    Design gradients follow from one VJP of `p(x)` (see `value_and_grad`); methods that work on
    the design directly (finite differences) override `value_and_grad_design`.
    """

    @abc.abstractmethod
    def value_and_grad_scene(self, case: FlexibleRodCase, scene: Scene, *, rtol: float, atol: float,
                             solver: diffrax.AbstractSolver, max_steps: int):
        """`(psi, dpsi/dp)` with `dpsi/dp` a pytree like `scene` (`None` for non-float leaves)."""

    def value_and_grad_design(self, case: FlexibleRodCase, x, *, rtol, atol, solver, max_steps):
        """`(psi, dpsi/dx)`: the scene-level gradient pulled back through `p(x)` with one VJP."""
        scene, pullback = eqx.filter_vjp(case.scene, x)
        psi, g_scene = self.value_and_grad_scene(case, scene, rtol=rtol, atol=atol, solver=solver,
                                                 max_steps=max_steps)
        (g_x,) = pullback(g_scene)
        return psi, g_x
