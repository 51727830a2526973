"""Reverse-mode automatic differentiation through the diffrax solver."""

import diffrax
import equinox as eqx

from ._base import AbstractSensitivity, parameters, problem_gradient, psi_of, with_parameters


class Autodiff(AbstractSensitivity):
    """`jax.grad` through the solver ("discretise-then-optimise"): exact derivative of the
    computed `psi`, with `diffrax.RecursiveCheckpointAdjoint` (binomial checkpointing).

    **Fields:** `checkpoints`: number of checkpoints (default: diffrax's choice from `max_steps`).
    """

    checkpoints: int | None = None

    def value_and_grad_problem(self, problem, *, rtol, atol, solver, max_steps):
        adjoint = diffrax.RecursiveCheckpointAdjoint(checkpoints=self.checkpoints)
        psi, grads = eqx.filter_value_and_grad(
            lambda params: psi_of(with_parameters(problem, params), rtol=rtol, atol=atol, solver=solver,
                                  max_steps=max_steps, adjoint=adjoint)
        )(parameters(problem))
        return psi, problem_gradient(problem, grads)
