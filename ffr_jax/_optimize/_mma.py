"""Svanberg's method of moving asymptotes (MMA) with any number of inequality constraints."""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._optimizer import AbstractOptimizer

# The default move limit of fj.MMA and of `ffr-jax optimize --mma-move`. Svanberg's 0.5 let the first two
# steps of the README's slider-crank run take the volume from 0.50 to 0.18 and psi up elevenfold, to a
# design too soft to assemble (issue 30); 0.2 is the limit of the CLI's runs, which converge.
DEFAULT_MOVE = 0.2


# With a Heaviside projection a step may change a physical density by up to this many move limits (see
# `projected_move`). Without the cap, the slider-crank family case 8 x 4 with the projection at beta = 32
# swung from psi/psi_0 = 0.20 to 5.9 in one update and the volume from 0.50 to 0.10 in three, each at the
# move limit; with it, the run held psi/psi_0 = 0.20 and the volume (issue 30).
PROJECTED_MOVE_FACTOR = 2.0


def projected_move(move, beta):
    """The move limit of a design variable under a projection of sharpness `beta`: `min(move, 2 move / s)`.

    `s = beta / (2 tanh(beta / 2))` is the largest slope of the projection `P_beta` (at `u = eta = 0.5`;
    1.08 at `beta = 1`, 16 at `beta = 32`), and the density filter's rows sum to one, so a change `m`
    of the design variables changes a physical density by at most `s m`: the physical densities then move
    by at most `2 move` per step at any `beta`, where MMA's convex approximation still describes the
    nonlinear projection.
    """
    slope = beta / (2.0 * jnp.tanh(0.5 * beta))
    return jnp.minimum(move, PROJECTED_MOVE_FACTOR * move / slope)


class MMAState(NamedTuple):
    """The memory of MMA between iterations (all arrays, so a checkpoint stores it leaf by leaf).

    - `iteration`: updates done so far, `k`.
    - `x_old1`, `x_old2`: `x_{k-1}`, `x_{k-2}` `(n,)` (equal to `x_0` before there are any).
    - `low`, `upp`: the asymptotes `L_k`, `U_k` of the last update `(n,)`.
    - `objective_scale`: the factor applied to `psi` and its gradient (fixed at the first update).
    """

    iteration: Int[Array, ""]
    x_old1: Float[Array, " n"]
    x_old2: Float[Array, " n"]
    low: Float[Array, " n"]
    upp: Float[Array, " n"]
    objective_scale: Float[Array, ""]


class MMA(AbstractOptimizer):
    """The method of moving asymptotes for `min psi(x)` subject to `g_i(x) <= 0`, `x_min <= x <= x_max`.

    Each update solves a convex separable approximation of the problem around `x_k`
    (Svanberg 1987; the form of his 2007 note, `mmasub` and `subsolv`):

        psi~(x) = sum_j p0_j / (U_j - x_j) + q0_j / (x_j - L_j),
        g~_i(x) = sum_j P_ij / (U_j - x_j) + Q_ij / (x_j - L_j) - b_i,

    with `p0_j = (U_j - x_j)^2 (1.001 max(dpsi/dx_j, 0) + 0.001 max(-dpsi/dx_j, 0) + 1e-5 / (x_max - x_min))`
    (and `q0`, `P`, `Q` alike), so that `psi~` and `g~_i` match the values and gradients at `x_k`.
    The asymptotes `L < x < U` start at `x_k -+ 0.5 (x_max - x_min)` and then widen (x 1.2) where
    a variable keeps moving the same way and tighten (x 0.7) where it oscillates; the step is
    limited to `[alpha, beta]`, `alpha = max(x_min, L + 0.1 (x - L), x - move (x_max - x_min))`.
    The subproblem, in Svanberg's standard form with artificial variables `y_i >= 0`, `z >= 0`,

        min psi~(x) + a0 z + sum_i (c_i y_i + d_i y_i^2 / 2)  s.t.  g~_i(x) - a_i z - y_i <= 0,

    (`a0 = 1`, `a_i = 0`, `c_i = c`, `d_i = d`: the standard nonlinear program, whose `y_i` stay
    zero when the constraints can be met and otherwise measure the violation MMA cannot remove)
    is solved by a primal-dual interior-point Newton method with the barrier parameter lowered from
    1 to `epsimin` by factors of 10. Everything runs in `jax.lax` loops of fixed structure, so an
    update is deterministic and jit-compiled once.

    `psi` is scaled by `objective_scale` (default: `1 / |psi(x_0)|`, fixed at the first update and
    kept in the state), so that the penalty `c = 1000` on the artificial variables dominates
    whatever the units of `psi`. The constraint objects of this package are already normalised
    (`g = value / bound - 1`).

    **Arguments:**
    - `x_min`, `x_max`: bounds of every design variable (`case.material.x_min`, 1).
    - `move`: the largest change of a variable per update, as a fraction of `x_max - x_min` (default
      0.2, as `ffr-jax optimize --mma-move`). In a run with a [`HeavisideProjection`][] (an update
      given `beta`), the limit is `min(move, 2 move / s_beta)`, `s_beta = beta / (2 tanh(beta / 2))`
      the projection's largest slope: a physical density then moves by at most `2 move` per step
      however sharp the projection (at `beta = 32`: 0.025 of the design variables).
    - `asymptote_init`, `asymptote_increase`, `asymptote_decrease`: Svanberg's `asyinit` (0.5),
      `asyincr` (1.2), `asydecr` (0.7).
    - `c`, `d`: the linear and quadratic penalties of the artificial variables (1000, 1).
    - `objective_scale`: fixed scale of `psi`, or `None` for `1 / |psi(x_0)|`.
    - `epsimin`: the last barrier parameter of the subproblem (1e-7).

    **Example:**
    ```python
    mma = fj.MMA(x_min=case.material.x_min, move=0.2)
    result = fj.optimize(fun, x0, mma, (volume, frequency), iterations=100, directory="run")
    ```

    !!! cite "References"
        K. Svanberg, "The method of moving asymptotes — a new method for structural
        optimization", Int. J. Numer. Methods Eng. 24 (1987) 359–373.
        K. Svanberg, "MMA and GCMMA — two methods for nonlinear optimization", KTH Stockholm,
        2007 (the `mmasub`/`subsolv` form used here).
    """

    x_min: float = eqx.field(static=True)
    x_max: float = eqx.field(static=True)
    move: float = eqx.field(static=True)
    asymptote_init: float = eqx.field(static=True)
    asymptote_increase: float = eqx.field(static=True)
    asymptote_decrease: float = eqx.field(static=True)
    c: float = eqx.field(static=True)
    d: float = eqx.field(static=True)
    objective_scale: float | None = eqx.field(static=True)
    epsimin: float = eqx.field(static=True)

    def __init__(self, x_min: float = 0.01, x_max: float = 1.0, *, move: float = DEFAULT_MOVE,
                 asymptote_init: float = 0.5, asymptote_increase: float = 1.2, asymptote_decrease: float = 0.7,
                 c: float = 1000.0, d: float = 1.0, objective_scale: float | None = None, epsimin: float = 1e-7):
        if not x_min < x_max:
            raise ValueError(f"MMA needs x_min < x_max, got x_min={x_min}, x_max={x_max}.")
        if not 0.0 < move <= 1.0:
            raise ValueError(f"The MMA move limit is a fraction of x_max - x_min in (0, 1], got {move}.")
        if not 0.0 < asymptote_init <= 1.0 or not asymptote_increase >= 1.0 or not 0.0 < asymptote_decrease <= 1.0:
            raise ValueError("MMA asymptotes: need 0 < asymptote_init <= 1, asymptote_increase >= 1 and "
                             f"0 < asymptote_decrease <= 1, got {asymptote_init}, {asymptote_increase}, "
                             f"{asymptote_decrease}.")
        if not (c > 0.0 and d >= 0.0):
            raise ValueError(f"MMA: the penalties of the artificial variables need c > 0, d >= 0, got c={c}, d={d}.")
        if objective_scale is not None and not objective_scale > 0.0:
            raise ValueError(f"MMA: objective_scale must be positive (or None), got {objective_scale}.")
        self.x_min, self.x_max = float(x_min), float(x_max)
        self.move = float(move)
        self.asymptote_init = float(asymptote_init)
        self.asymptote_increase = float(asymptote_increase)
        self.asymptote_decrease = float(asymptote_decrease)
        self.c, self.d = float(c), float(d)
        self.objective_scale = None if objective_scale is None else float(objective_scale)
        self.epsimin = float(epsimin)

    def with_move(self, move: float) -> "MMA":
        """The same method with another move limit (e.g. halved after a step too large; see [`optimize`][])."""
        return MMA(self.x_min, self.x_max, move=move, asymptote_init=self.asymptote_init,
                   asymptote_increase=self.asymptote_increase, asymptote_decrease=self.asymptote_decrease, c=self.c,
                   d=self.d, objective_scale=self.objective_scale, epsimin=self.epsimin)

    def start(self, x0, beta):
        del beta
        return jnp.clip(jnp.asarray(x0, dtype=float), self.x_min, self.x_max)

    def init(self, x):
        span = self.x_max - self.x_min
        scale = jnp.asarray(0.0 if self.objective_scale is None else self.objective_scale, dtype=x.dtype)
        return MMAState(jnp.zeros((), dtype=jnp.int64), x, x, x - self.asymptote_init * span,
                        x + self.asymptote_init * span, scale)

    def update(self, x, state, value, grad, g, dg, beta):
        span = self.x_max - self.x_min
        move = self.move if beta is None else projected_move(self.move, beta)
        if self.objective_scale is None:
            size = jnp.abs(value)
            first = jnp.where(size > 0.0, 1.0 / jnp.where(size > 0.0, size, 1.0), 1.0)
            scale = jnp.where(state.iteration == 0, first, state.objective_scale)
        else:
            scale = state.objective_scale
        low, upp = self._asymptotes(x, state)
        alfa = jnp.maximum(jnp.maximum(low + 0.1 * (x - low), x - move * span), self.x_min)
        beta_ = jnp.minimum(jnp.minimum(upp - 0.1 * (upp - x), x + move * span), self.x_max)

        ux1, xl1 = upp - x, x - low
        regular = 1e-5 / span
        df0 = scale * grad
        p0 = (jnp.maximum(df0, 0.0) + 0.001 * jnp.abs(df0) + regular) * ux1**2
        q0 = (jnp.maximum(-df0, 0.0) + 0.001 * jnp.abs(df0) + regular) * xl1**2
        p = (jnp.maximum(dg, 0.0) + 0.001 * jnp.abs(dg) + regular) * ux1**2
        q = (jnp.maximum(-dg, 0.0) + 0.001 * jnp.abs(dg) + regular) * xl1**2
        b = p @ (1.0 / ux1) + q @ (1.0 / xl1) - g
        m = g.shape[0]
        x_new = _subsolve(low, upp, alfa, beta_, p0, q0, p, q, b, jnp.full(m, self.c, x.dtype),
                          jnp.full(m, self.d, x.dtype), self.epsimin)
        return x_new, MMAState(state.iteration + 1, x, state.x_old1, low, upp, scale)

    def _asymptotes(self, x, state):
        """`L_k`, `U_k`: reset for the first two updates, then widened or tightened per variable."""
        span = self.x_max - self.x_min
        low0, upp0 = x - self.asymptote_init * span, x + self.asymptote_init * span
        trend = (x - state.x_old1) * (state.x_old1 - state.x_old2)
        factor = jnp.where(trend > 0.0, self.asymptote_increase, jnp.where(trend < 0.0, self.asymptote_decrease, 1.0))
        low = x - factor * (state.x_old1 - state.low)
        upp = x + factor * (state.upp - state.x_old1)
        low = jnp.clip(low, x - 10.0 * span, x - 0.01 * span)
        upp = jnp.clip(upp, x + 0.01 * span, x + 10.0 * span)
        early = state.iteration < 2
        return jnp.where(early, low0, low), jnp.where(early, upp0, upp)


class _Point(NamedTuple):
    """Primal and dual variables of the MMA subproblem (Svanberg 2007, `subsolv`)."""

    x: jax.Array
    y: jax.Array
    z: jax.Array
    lam: jax.Array
    xsi: jax.Array
    eta: jax.Array
    mu: jax.Array
    zet: jax.Array
    s: jax.Array


def _subsolve(low, upp, alfa, beta, p0, q0, p, q, b, c, d, epsimin):
    """The minimiser `x` of the MMA subproblem by a primal-dual Newton method (Svanberg's `subsolv`).

    For each barrier parameter `epsi = 1, 0.1, ..., epsimin` the perturbed KKT conditions are
    solved by damped Newton steps (at most 200 per `epsi`, step halved up to 50 times until the
    residual norm decreases). The Newton system is reduced to `m + 1` unknowns when `m < n` and to
    `n + 1` otherwise. `a0 = 1`, `a = 0` (the standard nonlinear program).
    """
    m, n = p.shape
    a0 = 1.0
    a = jnp.zeros(m, dtype=p0.dtype)

    def residual(v: _Point, epsi):
        ux1, xl1 = upp - v.x, v.x - low
        plam = p0 + p.T @ v.lam
        qlam = q0 + q.T @ v.lam
        gvec = p @ (1.0 / ux1) + q @ (1.0 / xl1)
        parts = (
            plam / ux1**2 - qlam / xl1**2 - v.xsi + v.eta,
            c + d * v.y - v.mu - v.lam,
            (a0 - v.zet - a @ v.lam)[None],
            gvec - a * v.z - v.y + v.s - b,
            v.xsi * (v.x - alfa) - epsi,
            v.eta * (beta - v.x) - epsi,
            v.mu * v.y - epsi,
            (v.zet * v.z - epsi)[None],
            v.lam * v.s - epsi,
        )
        r = jnp.concatenate(parts)
        return jnp.sqrt(r @ r), jnp.max(jnp.abs(r))

    def direction(v: _Point, epsi):
        ux1, xl1 = upp - v.x, v.x - low
        ux2, xl2 = ux1**2, xl1**2
        plam = p0 + p.T @ v.lam
        qlam = q0 + q.T @ v.lam
        gvec = p @ (1.0 / ux1) + q @ (1.0 / xl1)
        gg = p / ux2 - q / xl2
        delx = plam / ux2 - qlam / xl2 - epsi / (v.x - alfa) + epsi / (beta - v.x)
        dely = c + d * v.y - v.lam - epsi / v.y
        delz = a0 - a @ v.lam - epsi / v.z
        dellam = gvec - a * v.z - v.y - b + epsi / v.lam
        diagx = 2.0 * (plam / (ux2 * ux1) + qlam / (xl2 * xl1)) + v.xsi / (v.x - alfa) + v.eta / (beta - v.x)
        diagy = d + v.mu / v.y
        diaglamyi = v.s / v.lam + 1.0 / diagy
        if m < n:
            blam = dellam + dely / diagy - gg @ (delx / diagx)
            matrix = jnp.block([[jnp.diag(diaglamyi) + (gg / diagx) @ gg.T, a[:, None]],
                                [a[None, :], (-v.zet / v.z)[None, None]]])
            solution = jnp.linalg.solve(matrix, jnp.concatenate([blam, delz[None]]))
            dlam, dz = solution[:m], solution[m]
            dx = -delx / diagx - (gg.T @ dlam) / diagx
        else:
            dellamyi = dellam + dely / diagy
            axx = jnp.diag(diagx) + gg.T @ (gg / diaglamyi[:, None])
            azz = v.zet / v.z + a @ (a / diaglamyi)
            axz = -gg.T @ (a / diaglamyi)
            bx = delx + gg.T @ (dellamyi / diaglamyi)
            bz = delz - a @ (dellamyi / diaglamyi)
            matrix = jnp.block([[axx, axz[:, None]], [axz[None, :], azz[None, None]]])
            solution = jnp.linalg.solve(matrix, -jnp.concatenate([bx, bz[None]]))
            dx, dz = solution[:n], solution[n]
            dlam = (gg @ dx) / diaglamyi - dz * (a / diaglamyi) + dellamyi / diaglamyi
        dy = -dely / diagy + dlam / diagy
        return _Point(
            x=dx, y=dy, z=dz, lam=dlam,
            xsi=-v.xsi + epsi / (v.x - alfa) - (v.xsi * dx) / (v.x - alfa),
            eta=-v.eta + epsi / (beta - v.x) + (v.eta * dx) / (beta - v.x),
            mu=-v.mu + epsi / v.y - (v.mu * dy) / v.y,
            zet=-v.zet + epsi / v.z - v.zet * dz / v.z,
            s=-v.s + epsi / v.lam - (v.s * dlam) / v.lam,
        )

    def newton_step(carry):
        v, epsi, norm, _, count = carry
        dv = direction(v, epsi)
        positive = jnp.concatenate([v.y, v.z[None], v.lam, v.xsi, v.eta, v.mu, v.zet[None], v.s])
        d_positive = jnp.concatenate([dv.y, dv.z[None], dv.lam, dv.xsi, dv.eta, dv.mu, dv.zet[None], dv.s])
        # The longest step keeping every positive variable and x inside (alpha, beta), by 1 %.
        largest = jnp.maximum(jnp.max(-1.01 * d_positive / positive, initial=-jnp.inf),
                              jnp.maximum(jnp.max(-1.01 * dv.x / (v.x - alfa)), jnp.max(1.01 * dv.x / (beta - v.x))))
        step = 1.0 / jnp.maximum(largest, 1.0)

        def halve(search):
            _, _, _, step, tries = search
            trial = jax.tree.map(lambda u, du: u + step * du, v, dv)
            new_norm, new_max = residual(trial, epsi)
            return trial, new_norm, new_max, step / 2.0, tries + 1

        def worse(search):
            _, new_norm, _, _, tries = search
            return (new_norm > norm) & (tries < 50)

        v, new_norm, new_max, _, _ = jax.lax.while_loop(worse, halve, (v, 2.0 * norm, jnp.inf, step, 0))
        return v, epsi, new_norm, new_max, count + 1

    def not_converged(carry):
        _, epsi, _, residual_max, count = carry
        return (residual_max > 0.9 * epsi) & (count < 200)

    def barrier_stage(carry):
        v, epsi = carry
        norm, largest = residual(v, epsi)
        v, _, _, _, _ = jax.lax.while_loop(not_converged, newton_step, (v, epsi, norm, largest, 0))
        return v, 0.1 * epsi

    x = 0.5 * (alfa + beta)
    start = _Point(
        x=x, y=jnp.ones(m, x.dtype), z=jnp.ones((), x.dtype), lam=jnp.ones(m, x.dtype),
        xsi=jnp.maximum(1.0 / (x - alfa), 1.0), eta=jnp.maximum(1.0 / (beta - x), 1.0),
        mu=jnp.maximum(1.0, 0.5 * c), zet=jnp.ones((), x.dtype), s=jnp.ones(m, x.dtype),
    )
    v, _ = jax.lax.while_loop(lambda carry: carry[1] > epsimin, barrier_stage, (start, jnp.ones((), x.dtype)))
    return v.x
