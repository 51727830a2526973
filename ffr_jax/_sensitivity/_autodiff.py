"""Reverse-mode automatic differentiation through the diffrax solver."""

import diffrax
import equinox as eqx

from .._simulate import simulate
from ._base import AbstractSensitivity


def _psi(case, scene, rtol, atol, solver, max_steps, adjoint):
    return simulate(
        case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
        solver=solver, rtol=rtol, atol=atol, max_steps=max_steps, adjoint=adjoint, jump_ts=case.jump_ts,
    ).psi


class Autodiff(AbstractSensitivity):
    """`jax.grad` through the solver ("discretise-then-optimise"): exact derivative of the
    computed `psi`, with `diffrax.RecursiveCheckpointAdjoint` (binomial checkpointing).

    **Fields:** `checkpoints`: number of checkpoints (default: diffrax's choice from `max_steps`).
    """

    checkpoints: int | None = None

    def value_and_grad_scene(self, case, scene, *, rtol, atol, solver, max_steps):
        adjoint = diffrax.RecursiveCheckpointAdjoint(checkpoints=self.checkpoints)
        return eqx.filter_value_and_grad(
            lambda s: _psi(case, s, rtol, atol, solver, max_steps, adjoint)
        )(scene)
