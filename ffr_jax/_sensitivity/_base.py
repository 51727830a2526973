"""Abstract base of the sensitivity methods, and the parameters of a problem they differentiate."""

import abc

import diffrax
import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu

from .._dynamics._problem import Problem
from .._dynamics._simulate import solve_minimal


def parameters(problem: Problem):
    """What `psi` of a problem is differentiated with respect to: `(scene, objective, y0, z0)`."""
    return problem.scene, problem.objective, problem.y0, problem.z0


def with_parameters(problem: Problem, params) -> Problem:
    """The problem with `(scene, objective, y0, z0)` replaced."""
    return eqx.tree_at(lambda p: (p.scene, p.objective, p.y0, p.z0), problem, tuple(params))


def problem_gradient(problem: Problem, grads) -> Problem:
    """A pytree like `problem` holding `grads = (d/dscene, d/dobjective, d/dy0, d/dz0)`.

    Leaves that are not float arrays are `None` (as in `eqx.filter_grad`); the model's arrays
    (the Newton starting guess) get zeros, the exact derivative of `psi` with respect to them.
    """
    zeros = jtu.tree_map(jnp.zeros_like, eqx.filter(problem, eqx.is_inexact_array))
    return eqx.tree_at(lambda p: (p.scene, p.objective, p.y0, p.z0), zeros, tuple(grads),
                       is_leaf=lambda node: node is None)


def forward_solve(problem: Problem, *, rtol, atol, solver, max_steps, dense: bool = False, adjoint=None):
    """One forward solve of a problem with its objective (a [`Trajectory`][ffr_jax.Trajectory]; `dense`: with
    the solver's dense output), differentiable through the given diffrax adjoint."""
    obj = problem.objective
    return solve_minimal(
        problem.model, problem.scene, problem.t0, problem.t1, problem.y0, problem.z0,
        integrand=obj.integrand, terminal=obj.terminal, solver=solver, rtol=rtol, atol=atol, dense=dense,
        max_steps=max_steps, adjoint=adjoint, jump_ts=problem.jump_ts, dt0=problem.dt0,
    )


def psi_of(problem: Problem, *, rtol, atol, solver, max_steps, adjoint) -> jnp.ndarray:
    """`psi` of a problem by one forward solve, differentiable through the given diffrax adjoint."""
    return forward_solve(problem, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps, adjoint=adjoint).psi


class AbstractSensitivity(eqx.Module):
    """A way to compute `psi` and its gradient with respect to the arrays of a [`Problem`][]:
    the scene (body data, spring constants, force and law coefficients, ...), the objective's own
    arrays and the initial state `(y0, z0)`.

    Design gradients follow from one VJP of the design map `p(x)` (see `value_and_grad`);
    methods that work on the design directly (finite differences) override `value_and_grad_design`.
    """

    @abc.abstractmethod
    def value_and_grad_problem(self, problem: Problem, *, rtol: float, atol: float,
                               solver: diffrax.AbstractSolver | None, max_steps: int):
        """`(psi, dpsi/dproblem)`, the gradient a pytree like `problem` (see `problem_gradient`)."""

    def value_and_grad_scene(self, problem: Problem, scene, *, rtol, atol, solver, max_steps):
        """`(psi, dpsi/dp)` for the problem with parameters `scene`: a pytree like `scene`."""
        psi, grad = self.value_and_grad_problem(problem.with_scene(scene), rtol=rtol, atol=atol, solver=solver,
                                                max_steps=max_steps)
        return psi, grad.scene

    def value_and_grad_design(self, case, x, *, rtol, atol, solver, max_steps):
        """`(psi, dpsi/dx)`: the scene-level gradient pulled back through `p(x)` with one VJP."""
        scene, pullback = eqx.filter_vjp(case.scene, x)
        psi, g_scene = self.value_and_grad_scene(case.problem, scene, rtol=rtol, atol=atol, solver=solver,
                                                 max_steps=max_steps)
        (g_x,) = pullback(g_scene)
        return psi, g_x
