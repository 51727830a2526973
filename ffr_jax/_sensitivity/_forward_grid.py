"""The adjoint ODE integrated backward by a Rosenbrock method on the forward solve's accepted steps.

The backward ODE of paper eq. 43 in `lambda = (mu, w)` (`w = Mbar nu`) is linear,
`lambda' = -J(t)^T lambda - dF/dx^T`, with `J = d(y', z')/d(y, z)` the Jacobian of the minimal
equations of motion along the forward trajectory (the paper's `S1 = -dy'/dy`, and
`T1 = dR/dy = -Mbar dz'/dy` on the solution, so `S1^T mu + T1^T nu = -(dy'/dy)^T mu - (dz'/dy)^T w`;
the same for `S2`, `T2`). Three things follow for a Rosenbrock method, whose stage equations are
linear in the Jacobian of the right-hand side:

- that Jacobian is `-J^T`, formed by forward mode through the equations of motion (`2f`
  tangents, the cost of the forward solver's own Jacobian), not by differentiating the reverse
  pass of the adjoint right-hand side (forward over reverse, several times that);
- the stages of the linear ODE are solved exactly with it, no Newton iteration;
- the steps can be the forward solve's accepted steps, backward: the backward ODE has the
  eigenvalues of the forward one, and on each forward step the forward state is one polynomial
  (the step's dense output), so the backward right-hand side is smooth inside every step. An
  adaptive backward solve took 746 steps where the forward took 76 (10 x 2 case, 3 modes, rtol
  1e-8): it resolves the fast modes' free oscillations of the adjoint (below) and meets a kink of
  the forward dense output at every forward step boundary.

The price: the backward steps are not controlled by the backward tolerances. The backward solution
has free oscillations of the fast modes (excited where the adjoint starts from zero at `t1` against a
non-zero forcing) that the forward solve, starting from rest, hardly has; an L-stable step damps
them where the forward grid does not resolve them. Their share of the gradient is small: on the
reference case (6 modes, rtol 1e-8) the gradient is 8.9e-7 (max norm, relative) from a tight
reference, 2.4e-7 at rtol 1e-9 and 5e-9 at 1e-10 (benchmarks/RESULTS.md), while the embedded error
estimates of the backward steps, which see the damped oscillation, are far above the tolerance. They
are kept as a diagnostic ([`ForwardGridSolution.error`][]), not used as a guard; `Adjoint(grid="adaptive")`
resolves the oscillations with diffrax's step control, at several times the cost.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from .._dynamics._small_linalg import lu_factor
from .._solver._rosenbrock import AbstractRosenbrock, rosenbrock_stages


class ForwardGridSolution(eqx.Module):
    """The backward solve on the forward grid, shaped like diffrax's dense solution of a backward solve.

    - `ts`: `(max_steps + 1,)` solver times `tau = -t` (increasing), the first `ts_size` valid;
      `direction = -1`.
    - `infos`: per step (leading axis `max_steps`) the dense output of the backward step:
      `y0`, `y1` the state `(mu, w)` at its start and end, `k` the interpolant's coefficients.
    - `ys`: `((1, f), (1, f))`: `(mu, w)` at `t0`, as diffrax's `SaveAt(t1=True)`.
    - `error`: the largest scaled embedded error estimate over the backward steps (RMS over the
      state of `err / (atol + rtol max(|lambda_0|, |lambda_1|))`): a diagnostic, dominated by the
      unresolved fast oscillations of the adjoint (module docstring).
    """

    ts: jax.Array
    ts_size: jax.Array
    infos: dict
    ys: tuple
    error: jax.Array
    interpolation_cls: Callable = eqx.field(static=True)
    direction: int = eqx.field(static=True, default=-1)

    @property
    def interpolation(self):
        return self


def backward_on_forward_grid(solver: AbstractRosenbrock, forward_dense, field, accelerations, state1, *, rtol, atol):
    """Integrate `lambda' = field(t, y, z, mu, w)` from `t1` to `t0` on the forward's accepted steps.

    - `forward_dense`: the forward diffrax solution's `DenseInterpolation` (any solver's).
    - `field(t, y, z, mu, w) -> (dmu/dt, dw/dt)`: the adjoint right-hand side (paper eq. 43).
    - `accelerations(t, y, z) -> z'`: the minimal accelerations; `J = [[0, I], [z'_y, z'_z]]`.
    - `state1 = (mu(t1), w(t1))`.

    **Returns:** a [`ForwardGridSolution`][].
    """
    tab = solver.tableau
    ts, infos = forward_dense.ts, forward_dense.infos
    max_steps = ts.shape[0] - 1
    # A failed solve's step count is the largest integer in equinox's `nan` error mode (the cacheable programs):
    # the loop is bounded by the buffer, never by that count (issue 32: an endless loop after the step budget).
    # A count past the buffer is that of a failed solve: no step then (its error is reported by the caller).
    n_steps = jnp.where(forward_dense.ts_size - 1 > max_steps, 0, forward_dense.ts_size - 1)
    mu1, w1 = state1
    f = mu1.shape[0]
    n = 2 * f
    dtype = mu1.dtype
    r = tab.dense.shape[0]
    eye_f = jnp.eye(f, dtype=dtype)

    def step(k, lam_a):
        """Backward step from `t_{k+1}` to `t_k` on forward step `k`."""
        t_a, t_b = ts[k + 1], ts[k]
        h = t_b - t_a
        local = forward_dense.interpolation_cls(t0=ts[k], t1=ts[k + 1], **jtu.tree_map(lambda a: a[k], infos))

        def rhs(t, lam):
            state = local.evaluate(t)
            d_mu, d_w = field(t, state[0], state[1], lam[:f], lam[f:])
            return jnp.concatenate([d_mu, d_w])

        def g(t, lam):
            return h * rhs(t, lam)

        f0 = rhs(t_a, lam_a)
        # d rhs / dt by a one-sided second-order difference into the step (the drivers may switch
        # piece at t_a): two reverse passes, against the five of a forward-over-reverse JVP. On
        # the step the right-hand side is smooth on the scale of the step (the forward state is
        # the step's polynomial), so with delta = 1e-5 h truncation (~delta^2 / h^2) and rounding
        # (~eps h / delta) are ~1e-10 of |f| / h; f_t enters the stages multiplied by h^2 d_i.
        # Measured: the gradient equals that with the exact JVP to 7e-13 (10 x 2 case, rtol 1e-8..1e-10).
        delta = 1e-5 * (t_a - t_b)
        f_t = (3 * f0 - 4 * rhs(t_a - delta, lam_a) + rhs(t_a - 2 * delta, lam_a)) / (2 * delta)
        state = local.evaluate(t_a)
        a_y, a_z = jax.jacfwd(accelerations, argnums=(1, 2))(t_a, state[0], state[1])
        # J^T = [[0, a_y^T], [I, a_z^T]]; the right-hand side's Jacobian is -J^T, so
        # I / gamma - h (-J^T) = I / gamma + h J^T.
        jac_t = jnp.block([[jnp.zeros((f, f), dtype), a_y.T], [eye_f, a_z.T]])
        matrix = jnp.eye(n, dtype=dtype) / tab.gamma + h * jac_t
        lu = lu_factor(matrix)
        ks = rosenbrock_stages(tab, g, t_a, h, lam_a, h * f0, h * f_t, matrix, lu)
        lam_b = lam_a + jnp.asarray(tab.b, dtype) @ ks
        err = jnp.asarray(tab.b_error, dtype) @ ks
        scale = atol + rtol * jnp.maximum(jnp.abs(lam_a), jnp.abs(lam_b))
        error = jnp.sqrt(jnp.mean((err / scale) ** 2))
        return lam_b, jnp.asarray(tab.dense, dtype) @ ks, error

    def body(carry):
        j, lam, buffers, worst = carry
        k = n_steps - 1 - j
        lam_b, dense, error = step(k, lam)
        b_y0, b_y1, b_k = buffers
        buffers = (b_y0.at[j].set(lam), b_y1.at[j].set(lam_b), b_k.at[j].set(dense))
        return j + 1, lam_b, buffers, jnp.maximum(worst, error)

    lam1 = jnp.concatenate([mu1, w1])
    buffers = (jnp.zeros((max_steps, n), dtype), jnp.zeros((max_steps, n), dtype), jnp.zeros((max_steps, r, n), dtype))
    _, lam0, (b_y0, b_y1, b_k), worst = jax.lax.while_loop(
        lambda carry: carry[0] < n_steps, body, (jnp.zeros((), n_steps.dtype), lam1, buffers, jnp.zeros((), dtype)))

    def split(a):
        return a[..., :f], a[..., f:]

    # Solver time tau = -t; entry j of ts is the start of backward step j, i.e. t_{N - j}.
    index = jnp.arange(max_steps + 1)
    tau = jnp.where(index <= n_steps, -ts[jnp.clip(n_steps - index, 0, max_steps)], jnp.inf)
    return ForwardGridSolution(
        ts=tau, ts_size=n_steps + 1, infos=dict(y0=split(b_y0), y1=split(b_y1), k=split(b_k)),
        ys=(lam0[None, :f], lam0[None, f:]), error=worst, interpolation_cls=solver.interpolation_cls,
    )
