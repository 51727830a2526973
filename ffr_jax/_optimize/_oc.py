"""The optimality-criteria update (Bendsøe and Sigmund) as an optax gradient transformation."""

import jax
import jax.numpy as jnp
import optax

from ._volume import VolumeConstraint


def optimality_criteria(constraint: VolumeConstraint, *, move: float = 0.05, damping: float = 0.5,
                        iterations: int = 100) -> optax.GradientTransformation:
    """The classic optimality-criteria (OC) update for a volume-constrained minimisation.

    With sensitivities `g = dpsi/dx` and volume weights `c` (`dV/dx_e = c_e / n`), the update is

        x_new_e = clip(x_e B_e^eta, max(x_min, x_e - m), min(1, x_e + m)),
        B_e = (s - g_e / c_e) / lambda,   s = max(0, max_k g_k / c_k),

    with damping `eta` and move limit `m`; the multiplier `lambda` is found by bisection (on
    `log lambda`, since the scale of `g` is arbitrary) such that `mean(c x_new) = V`.

    When every `g_e <= 0` (static compliance), `s = 0` and this is the textbook update
    `B_e = -g_e / (lambda c_e)`. But `psi` of a dynamic problem is not monotone in the densities:
    mass enters the inertia, so `dpsi/dx_e > 0` for some elements, where the textbook `B_e` would
    be negative and `B_e^eta` undefined. We then shift the sensitivities by a multiple of the
    volume gradient, `g - s c`. The shift is absorbed by the multiplier, so a KKT point stays in
    place under the update and the projection after it, whatever the sign of its multiplier; the
    element with the largest `g_e / c_e` gets `B_e = 0` and drops by the move limit, and the
    others move by how much less their density raises `psi`. (The plain clamp `max(-g_e, 0)`
    would drop every element with `g_e > 0` by the full move limit, even at a KKT point whose
    multiplier is negative.) Where the move limit makes `V` unreachable, the bisection stops at
    the nearest reachable volume; the projection that follows every update in [`make_step`][]
    restores `V` exactly.

    The default move limit is 0.05, not the textbook 0.2: on the tiny slider–crank
    (`nx=12, ny=2, t1=0.2`) a move of 0.2 makes `psi` oscillate between +6 % and +15 % of its
    start value, while 0.05 lowers it by 3 % in two steps (then it stalls; Adam keeps going).

    **Arguments:**
    - `constraint`: the volume constraint (target `V`, `x_min`, weights `c`).
    - `move`: move limit `m` per update; `damping`: the exponent `eta` (0.5 classically).
    - `iterations`: bisection steps on `log lambda`.

    **Returns:** an `optax.GradientTransformation` whose `update(grads, state, params)` needs the
    current design as `params` and returns `updates = x_new - x`.

    **Example:**
    ```python
    opt = fj.optimality_criteria(fj.VolumeConstraint(0.5), move=0.05)
    updates, state = opt.update(grad, opt.init(x), x)
    ```

    !!! cite "References"
        M. P. Bendsøe, O. Sigmund, *Topology Optimization: Theory, Methods and Applications*,
        Springer 2003, Sect. 1.2.1. E. Andreassen et al., "Efficient topology optimization in
        MATLAB using 88 lines of code", Struct. Multidiscip. Optim. 43 (2011) 1–16.
    """
    if not move > 0.0:
        raise ValueError(f"The OC move limit must be positive, got {move}.")
    if not 0.0 < damping <= 1.0:
        raise ValueError(f"The OC damping exponent eta must lie in (0, 1], got {damping}.")

    def init_fn(params):
        del params
        return optax.EmptyState()

    def update_fn(updates, state, params=None):
        if params is None:
            raise ValueError("optimality_criteria needs the current design: call update(grads, state, x).")
        x, g = params, updates
        c = jnp.ones_like(x) if constraint.weights is None else constraint.weights
        lower = jnp.maximum(constraint.x_min, x - move)
        upper = jnp.minimum(1.0, x + move)
        ratio = g / c
        b = jnp.maximum(jnp.max(ratio), 0.0) - ratio  # -g / c unless some g > 0: then shifted
        active = b > 0.0
        log_b = jnp.log(jnp.where(active, b, 1.0))

        def x_of(log_lam):
            scaled = x * jnp.exp(damping * (log_b - log_lam))
            return jnp.clip(jnp.where(active, scaled, 0.0), lower, upper)

        def bisect(_, bracket):
            lo, hi = bracket
            mid = 0.5 * (lo + hi)
            above = jnp.mean(c * x_of(mid)) > constraint.volume
            return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

        # Below lo every active element sits at its upper limit, above hi at its lower limit.
        lo = jnp.min(jnp.where(active, log_b + jnp.log(x / upper) / damping, jnp.inf))
        hi = jnp.max(jnp.where(active, log_b + jnp.log(x / lower) / damping, -jnp.inf))
        lo, hi = jnp.where(jnp.any(active), lo, 0.0), jnp.where(jnp.any(active), hi, 0.0)
        lo, hi = jax.lax.fori_loop(0, iterations, bisect, (lo, hi))
        return x_of(0.5 * (lo + hi)) - x, state

    return optax.GradientTransformation(init_fn, update_fn)
