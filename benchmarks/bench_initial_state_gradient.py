"""Gradients with respect to the initial state: which method converges to the derivative (issue 26 finding).

`d psi / d y0` and `d psi / d z0` of `fj.cases.slider_crank(4, 2, 2, 0.1)` at a non-uniform design (its
independent coordinates are the rod's two modal coordinates; y0 = z0 = 0), by
- central differences of `psi` at rtol 1e-12 for three steps (1e-3, 1e-4, 1e-5: they agree to 7 digits, so
  they give the derivative to that accuracy),
- the paper's adjoint (forward rtol 1e-12) with its backward tolerance 1e-8 (the default), 1e-10 and 1e-12,
- autodiff through the solver at rtol 1e-8, 1e-10 and 1e-12,
- the discrete adjoint of Rodas5P at rtol 1e-10 (the default route's method).

Usage: `python benchmarks/bench_initial_state_gradient.py` (minutes: every row compiles its own program).
Prints a Markdown table of `d psi / d q_2(0)` (the entry that differs) and the largest deviation over all
four initial-state entries relative to the largest entry.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj


def main():
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    x = case.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(case.n_design, dtype=float))
    problem = case.problem_for(x)
    tight = dict(rtol=1e-12, atol=1e-14)

    def psi_at(y0):
        return float(fj.objective(eqx.tree_at(lambda p: p.y0, problem, y0), **tight))

    fd = {}
    for h in (1e-3, 1e-4, 1e-5):
        fd[h] = np.array([(psi_at(problem.y0.at[k].add(h)) - psi_at(problem.y0.at[k].add(-h))) / (2 * h)
                          for k in range(problem.y0.size)])
    reference = fd[1e-5]
    rows = [(f"central differences, h = {h:g}, rtol 1e-12", g) for h, g in fd.items()]
    for rb in (1e-8, 1e-10, 1e-12):
        _, g = fj.value_and_grad(problem, method=fj.Adjoint(rtol=rb, atol=rb / 100), **tight)
        rows.append((f"adjoint, forward rtol 1e-12, backward rtol {rb:g}", np.asarray(g.y0)))
    for r in (1e-8, 1e-10, 1e-12):
        _, g = fj.value_and_grad(problem, method="autodiff", rtol=r, atol=r / 100)
        rows.append((f"autodiff, rtol {r:g}", np.asarray(g.y0)))
    _, g = fj.value_and_grad(problem, method="discrete-adjoint", solver=fj.Rodas5P(), rtol=1e-10, atol=1e-12)
    rows.append(("discrete adjoint of Rodas5P, rtol 1e-10", np.asarray(g.y0)))

    print("| method | d psi / d q_2(0) | relative to central differences | max deviation / max \\|g\\| |")
    print("|---|---:|---:|---:|")
    scale = np.max(np.abs(reference))
    for name, g in rows:
        print(f"| {name} | {g[1]:.6e} | {abs(g[1] - reference[1]) / abs(reference[1]):.1e} | "
              f"{np.max(np.abs(g - reference)) / scale:.1e} |")


if __name__ == "__main__":
    main()
