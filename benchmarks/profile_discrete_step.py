"""Where one backward step of the discrete adjoint of Rodas5P spends its time, against one forward step (issue 15).

At one step of the reference case's forward solve (the accepted step halfway through, Rodas5P at `--rtol`), each
piece below is compiled into one program that runs it `--reps` times in a `fori_loop` (the state perturbed by
the loop's carry so nothing is hoisted out of it; the parameters are loop-invariant, as in the backward loop),
so that dispatch is excluded as inside a solve; the median of 5 such programs per piece, in microseconds:

- `eval`: the vector field `g = h f(t, u, p)`; `jacobian`: `g`, `g_t`, `I / gamma - g_u` (`rosenbrock_matrix`);
- `forward step`: the Jacobian, its LU and the eight stages (what the solver does per step, without controller);
- `vjp u`, `vjp u, p`: one VJP of `g` with respect to the state, and to the state and the parameters;
- `second-order u`, `second-order u, p`: the gradient of the step start's terms (`phi` of
  `ffr_jax/_sensitivity/_discrete_adjoint.py`: the reverse pass over the `s + 1` directional derivatives);
- `step transpose`: the whole backward step (`step_transpose`): the recomputed step, `s - 1` VJPs with
  respect to `(u, p)` in a reverse scan, the second-order terms.

Usage: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/profile_discrete_step.py --modes 6 30`
"""

import argparse
import os
import statistics
import time

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import jax.tree_util as jtu

import ffr_jax as fj
from ffr_jax._sensitivity._base import forward_solve
from ffr_jax._sensitivity._discrete_adjoint import _vector_field, step_transpose
from ffr_jax._dynamics._small_linalg import lu_factor
from ffr_jax._solver._rosenbrock import rosenbrock_matrix, rosenbrock_stages


def in_loop(piece, args, reps):
    """Median microseconds per call of `piece(u, *args)` run `reps` times inside one compiled loop."""
    u0, *rest = args

    @jax.jit
    def run(u0, *rest):
        def body(i, acc):
            out = piece(u0 + 1e-30 * acc, *rest)
            return acc + sum(jnp.sum(leaf) for leaf in jtu.tree_leaves(out))
        return jax.lax.fori_loop(0, reps, body, jnp.zeros((), u0.dtype))

    run(u0, *rest).block_until_ready()
    samples = []
    for _ in range(5):
        start = time.perf_counter()
        run(u0, *rest).block_until_ready()
        samples.append((time.perf_counter() - start) / reps * 1e6)
    return statistics.median(samples)


def profile(n_modes, rtol, reps):
    case = fj.cases.slider_crank(n_modes=n_modes)
    problem = case.problem_for(case.initial_design(0.5))
    solver = fj.Rodas5P()
    tab = solver.tableau
    forward = eqx.filter_jit(lambda pr: forward_solve(pr, rtol=rtol, atol=rtol * 1e-2, solver=solver,
                                                      max_steps=200_000, dense=True))(problem)
    dense = forward.solution.interpolation
    k = int(dense.ts_size - 1) // 2
    starts = dense.infos["y0"]
    u0, unravel_u = jax.flatten_util.ravel_pytree(jtu.tree_map(lambda a: a[k], starts))
    t0, h = dense.ts[k], dense.ts[k + 1] - dense.ts[k]
    dynamic, static = eqx.partition((problem.scene, problem.objective), eqx.is_inexact_array)
    p, unravel_p = jax.flatten_util.ravel_pytree(dynamic)
    field = _vector_field(problem)

    def g(t, u, q):
        return h * jax.flatten_util.ravel_pytree(field(t, unravel_u(u), eqx.combine(unravel_p(q), static)))[0]

    s, n = tab.stages, u0.shape[0]
    ks = jnp.full((s, n), 1e-3 * jnp.max(jnp.abs(u0)))  # stage-sized directions and unit cotangents
    rbars = jnp.ones((s + 1, n))

    def second_order(u, q, wrt):
        def phi(u, q):
            values, derivatives = jax.vmap(lambda dt, du: jax.jvp(lambda tt, uu: g(tt, uu, q), (t0, u), (dt, du)))(
                jnp.zeros(s + 1).at[s].set(1.0), jnp.concatenate([ks, jnp.zeros((1, n))]))
            return rbars[0] @ values[0] + jnp.sum(rbars * derivatives)
        return jax.grad(phi, argnums=wrt)(u, q)

    def forward_step(u, q):
        g0, g_t, matrix = rosenbrock_matrix(tab, lambda t, uu: g(t, uu, q), t0, u)
        return rosenbrock_stages(tab, lambda t, uu: g(t, uu, q), t0, h, u, g0, g_t, matrix, lu_factor(matrix))

    pieces = {
        "eval": lambda u, q: g(t0, u, q),
        "jacobian": lambda u, q: rosenbrock_matrix(tab, lambda t, uu: g(t, uu, q), t0, u),
        "forward step": forward_step,
        "vjp u": lambda u, q: jax.vjp(lambda uu: g(t0, uu, q), u)[1](u),
        "vjp u, p": lambda u, q: jax.vjp(lambda uu, qq: g(t0, uu, qq), u, q)[1](u),
        "second-order u": lambda u, q: second_order(u, q, 0),
        "second-order u, p": lambda u, q: second_order(u, q, (0, 1)),
        "step transpose": lambda u, q: step_transpose(tab, g, t0, h, u, q, jnp.ones_like(u)),
    }
    return n, {name: in_loop(piece, (u0, p), reps) for name, piece in pieces.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[6, 30])
    parser.add_argument("--rtol", type=float, default=1e-7)
    parser.add_argument("--reps", type=int, default=300)
    args = parser.parse_args()
    rows = {m: profile(m, args.rtol, args.reps) for m in args.modes}
    print(f"Load average at the end: {os.getloadavg()[0]:.2f}; XLA_FLAGS={os.environ.get('XLA_FLAGS', '(default)')}")
    print("| piece | " + " | ".join(f"{m} modes (n = {rows[m][0]}) [us]" for m in args.modes) + " |")
    print("|---|" + "---:|" * len(args.modes))
    for name in rows[args.modes[0]][1]:
        print(f"| {name} | " + " | ".join(f"{rows[m][1][name]:.1f}" for m in args.modes) + " |")
    print("| step transpose / forward step | " + " | ".join(
        f"{rows[m][1]['step transpose'] / rows[m][1]['forward step']:.1f}" for m in args.modes) + " |")


if __name__ == "__main__":
    main()
