"""The discrete adjoint of a Rosenbrock method: the exact gradient of the computed `psi`, step by step backward.

A Rosenbrock step (`ffr_jax/_solver/_rosenbrock.py`, in the `g = h f` form the solver uses) maps the
start state `u0 = (y, z, psi)` and the parameters `p` to

`k_i = W^-1 r_i`, `r_i = g(t_i, U_i) + d_i h g_t + sum_j C_ij k_j`, `U_i = u0 + sum_j a_ij k_j`,
`u1 = u0 + sum_i b_i k_i`, with `W = I / gamma - g_u(t0, u0)`, `g_t = g_t(t0, u0)`.

Its transpose, for a cotangent `u1bar` of the step's end (`kbar_i = b_i u1bar` to start, the stages
taken last to first, each `kbar_i` complete when stage `i` is reached since `a`, `C` are strictly lower):

- `rbar_i = W^-T kbar_i` (the forward step's matrix, transposed: one LU, no derivative of it);
- `kbar_j += C_ij rbar_i`, `gtbar += d_i h rbar_i`; for `i >= 2` the VJP of `g` at the stage point,
  `(Ubar, pbar_i) = (g_u, g_p)(t_i, U_i)^T rbar_i`, then `u0bar += Ubar`, `kbar_j += a_ij Ubar`;
- the step start's own terms (`g0 = g(t0, u0)` in `r_1`, the Jacobian in `W`, `g_t`) as the gradient
  with respect to `(u0, p)` of the scalar
  `phi = rbar_1 . g(t0, u0) + sum_i rbar_i . g_u(t0, u0) k_i + gtbar . g_t(t0, u0)`
  (`dk_i = W^-1 (dr_i + dg_u k_i)`): one reverse pass over `s + 1` directional derivatives,
  where differentiating the Jacobian as a whole costs a reverse pass over all `n + 1` of its columns
  (what `jax.grad` through the solver does).

The step sizes are those the forward solve accepted, held fixed (diffrax's step controller stops
gradients the same way), so the result is the derivative of the discrete `psi`: `jax.grad` through
the solver gives the same numbers (tests/test_discrete_adjoint.py), at a fraction of the cost and
memory, since nothing is recomputed from checkpoints. Unlike the paper's continuous adjoint
([`Adjoint`][ffr_jax.Adjoint]) solved on the forward grid, it carries the forward step's own damping
of the fast modes, so its error against the exact gradient follows the forward solve's global error
(benchmarks/RESULTS.md, "The discrete adjoint of Rodas5P: cost and accuracy against retained modes").
"""

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import jax.tree_util as jtu

from .._dynamics._problem import Problem
from .._dynamics._simulate import minimal_vector_field
from .._dynamics._small_linalg import lu_factor, lu_solve
from .._solver._rodas5p import Rodas5P
from .._solver._rosenbrock import AbstractRosenbrock, rosenbrock_matrix, rosenbrock_stages
from ._base import AbstractSensitivity, forward_solve, problem_gradient


def _vector_field(problem: Problem):
    """The right-hand side `solve_minimal` integrates, as a function of `(t, state, (scene, objective))`."""

    def field(t, state, params):
        return minimal_vector_field(problem.model, t, state, params[0], params[1].integrand)

    return field


def step_transpose(tab, g, t0, h, u0, p, u1bar):
    """`(u0bar, pbar)` of one Rosenbrock step `u1 = step(u0, p)` for the cotangent `u1bar` (module docstring).

    `g(t, u, p) = h f(t, u, p)` on flat `u` `(n,)` and flat `p`; the step is recomputed from `u0`.
    """
    s, n, dtype = tab.stages, u0.shape[0], u0.dtype

    def g_of(t, u):
        return g(t, u, p)

    g0, g_t, matrix = rosenbrock_matrix(tab, g_of, t0, u0)
    lu = lu_factor(matrix)
    ks = rosenbrock_stages(tab, g_of, t0, h, u0, g0, g_t, matrix, lu)

    a = jnp.asarray(tab.a, dtype)
    coupling = jnp.asarray(tab.c_coupling, dtype)
    c = jnp.asarray(tab.c, dtype)
    d = jnp.asarray(tab.d, dtype)
    points = u0[None, :] + a @ ks  # (s, n) stage points U_i

    def stage(carry, i):
        kbar, u0bar, pbar, gtbar = carry
        rbar = lu_solve(lu, kbar[i], trans=1)
        gtbar = gtbar + (d[i] * h) * rbar
        kbar = kbar + coupling[i][:, None] * rbar[None, :]
        _, pull = jax.vjp(lambda u, q: g(t0 + c[i] * h, u, q), points[i], p)
        ubar_i, pbar_i = pull(rbar)
        kbar = kbar + a[i][:, None] * ubar_i[None, :]
        return (kbar, u0bar + ubar_i, pbar + pbar_i, gtbar), rbar

    kbar = jnp.asarray(tab.b, dtype)[:, None] * u1bar[None, :]
    init = (kbar, u1bar, jnp.zeros_like(p), jnp.zeros(n, dtype))
    (kbar, u0bar, pbar, gtbar), rbars = jax.lax.scan(stage, init, jnp.arange(s - 1, 0, -1))
    rbar1 = lu_solve(lu, kbar[0], trans=1)
    gtbar = gtbar + (d[0] * h) * rbar1
    rbars = jnp.concatenate([rbar1[None, :], rbars[::-1]])  # (s, n), stage order

    def phi(u, q):
        def one(dt, du):
            return jax.jvp(lambda tt, uu: g(tt, uu, q), (t0, u), (dt, du))

        values, derivatives = jax.vmap(one)(jnp.zeros(s + 1, dtype).at[s].set(1.0),
                                            jnp.concatenate([ks, jnp.zeros((1, n), dtype)]))
        return rbar1 @ values[0] + jnp.sum(rbars * derivatives[:s]) + gtbar @ derivatives[s]

    u0bar_phi, pbar_phi = jax.grad(phi, argnums=(0, 1))(u0, p)
    return u0bar + u0bar_phi, pbar + pbar_phi


class DiscreteAdjoint(AbstractSensitivity):
    """The discrete adjoint of a Rosenbrock method ("discretise-then-optimise", by hand): the exact
    derivative of the computed `psi`, as `jax.grad` through the solver, without its checkpointing and
    without differentiating the Jacobian column by column (`ffr_jax/_sensitivity/_discrete_adjoint.py`).

    The forward solve keeps its accepted steps (dense output); the backward recursion transposes them
    one at a time, last to first, each recomputed from its start state. The forward solver must be a
    Rosenbrock method (`ffr_jax.Rodas5P()`, the stiff route; `solver=None` means `Rodas5P()` here).

    Memory: the forward's dense output (what [`Adjoint`][ffr_jax.Adjoint] keeps too) and one step's
    stages; the backward pass costs about one forward step, `s - 1` VJPs of the equations of motion and
    one reverse pass over `s + 1` of their JVPs per step.
    """

    def value_and_grad_problem(self, problem: Problem, *, rtol, atol, solver, max_steps):
        solver = Rodas5P() if solver is None else solver
        if not isinstance(solver, AbstractRosenbrock):
            raise ValueError(
                f"DiscreteAdjoint transposes the steps of a Rosenbrock method; got solver={type(solver).__name__}. "
                "Pass solver=ffr_jax.Rodas5P() (or leave solver unset), or use method='adjoint' or 'autodiff' "
                "with other solvers.")
        obj = problem.objective
        forward = forward_solve(problem, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps, dense=True)
        params = (problem.scene, problem.objective)
        dynamic, static = eqx.partition(params, eqx.is_inexact_array)
        p_flat, unravel_p = jax.flatten_util.ravel_pytree(dynamic)
        field = _vector_field(problem)
        dense = forward.solution.interpolation
        ts, starts = dense.ts, dense.infos["y0"]
        # A failed solve's step count is the largest integer in equinox's `nan` error mode (the cacheable programs):
        # the loop is bounded by the buffer, never by that count (issue 32: an endless loop after the step budget).
        # A count past the buffer is that of a failed solve: no step then (its error is reported by the caller).
        n_steps = jnp.where(dense.ts_size > ts.shape[0], 0, dense.ts_size - 1)
        state_template = jtu.tree_map(lambda a: a[0], starts)
        u_template, unravel_u = jax.flatten_util.ravel_pytree(state_template)
        dtype = u_template.dtype
        f = problem.y0.shape[0]

        def g_flat(h):
            def g(t, u, q):
                return h * jax.flatten_util.ravel_pytree(field(t, unravel_u(u), eqx.combine(unravel_p(q), static)))[0]
            return g

        # End condition: d psi / d u(t1) = (dG/dy, dG/dz, 1) (the last entry the integral's, if any).
        u1bar = jnp.zeros_like(u_template)
        pbar = jnp.zeros_like(p_flat)
        if obj.integrand is not None:
            u1bar = u1bar.at[2 * f].set(1.0)
        if obj.terminal is not None:
            t1 = jnp.asarray(problem.t1, dtype)

            def terminal(y, z, q):
                scene, objective = eqx.combine(unravel_p(q), static)
                y_r, z_r = problem.model.state(t1, y, z, scene)
                return objective.terminal(t1, y_r, z_r, scene)

            g_y, g_z, g_p = jax.grad(terminal, argnums=(0, 1, 2))(forward.ys[-1], forward.zs[-1], p_flat)
            u1bar = u1bar.at[:f].add(g_y).at[f:2 * f].add(g_z)
            pbar = pbar + g_p

        # Where a step ends at a driver's switch time j, diffrax ends it at prevbefore(j) and starts the
        # next one at nextafter(j) (the dense output keeps only the starts): the step's last stages
        # (c_i = 1) were taken on the piece before the switch, and must be recomputed there.
        jumps = [jnp.asarray(j, dtype) for j in problem.jump_ts if problem.t0 < j < problem.t1]

        def step_end(k):
            end = ts[k + 1]
            for j in jumps:
                end = jnp.where(end == jnp.nextafter(j, jnp.inf), jnp.nextafter(j, -jnp.inf), end)
            return end

        def body(carry):
            k, ubar, pbar = carry
            # Under `jax.vmap` the loop runs until the longest solve of the batch is done, and the
            # finished members' results are discarded: keep their (unused) steps valid ones.
            i = jnp.maximum(k, 0)
            t0, h = ts[i], step_end(i) - ts[i]
            u0 = jax.flatten_util.ravel_pytree(jtu.tree_map(lambda a: a[i], starts))[0]
            u0bar, pbar_k = step_transpose(solver.tableau, g_flat(h), t0, h, u0, p_flat, ubar)
            return k - 1, u0bar, pbar + pbar_k

        _, u0bar, pbar = jax.lax.while_loop(lambda carry: carry[0] >= 0, body, (n_steps - 1, u1bar, pbar))
        g_scene, g_objective = unravel_p(pbar)
        return forward.psi, problem_gradient(problem, (g_scene, g_objective, u0bar[:f], u0bar[f:2 * f]))
