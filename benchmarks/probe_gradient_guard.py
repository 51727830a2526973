"""Issue 15, probe finding 2: an untrustworthy autodiff gradient at 20 modes, and a cheap guard.

On `slider_crank(12, 2, 20, 0.2)` at `x = 0.5`, every method's gradient (autodiff, adjoint,
backsolve through Dopri8 at the default rtol 1e-10, autodiff at rtol 1e-12, and the stiff route:
Rodas5P forward and backward) is compared with central finite differences of psi along two
directions (the normalised gradient itself and a fixed random +-1 direction, steps 1e-4 and 1e-3,
psi at rtol 1e-12 with Dopri8), and with the adjoint at rtol 1e-12.

The guard: `directional_check(psi_fn, x, grad, direction, step)` compares the directional
derivative `grad . d` with `(psi(x + h d) - psi(x - h d)) / 2h` computed by the *same* forward solve
the gradient came from (two forward solves). A gradient that is the derivative of a discrete
solution whose step sequence is driven by the stability limit, rather than of the solution,
fails it by orders of magnitude; its cost is reported as a fraction of the gradient's.

Usage: `python benchmarks/probe_gradient_guard.py [--modes 20] [--runs 3] [--only method:solver:rtol ...] [--out benchmarks/results/gradient_guard.json]`
(each row is written to `--out` as it finishes)
"""

import argparse
import json
import os
import resource
import pathlib
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax
from ffr_jax._solver import Rodas5P

HERE = pathlib.Path(__file__).parent
sys.path.insert(0, str(HERE))
from _results import timed  # noqa: E402


def directional_check(psi_fn, x, grad, direction, step):
    """`(grad . d, central difference of psi along d, relative disagreement)` for a unit direction `d`.

    The relative disagreement is `|g.d - fd| / max(|g.d|, |fd|)`; `psi_fn` should be the forward
    solve with the settings of the gradient (its noise, about rtol * psi / step, bounds what the
    check can resolve).
    """
    plus, minus = psi_fn(x + step * direction), psi_fn(x - step * direction)
    fd = float((plus - minus) / (2 * step))
    gd = float(jnp.dot(grad, direction))
    return gd, fd, abs(gd - fd) / max(abs(gd), abs(fd), 1e-300)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, default=20)
    parser.add_argument("--out", default=str(HERE / "results" / "gradient_guard.json"))
    parser.add_argument("--only", nargs="*", default=None, help="configs as method:solver:rtol, e.g. adjoint:rodas5p:1e-10")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per gradient (median), after one warm-up")
    args = parser.parse_args()
    case = ffr_jax.cases.slider_crank(12, 2, args.modes, 0.2)
    x = case.initial_design(0.5)
    rng = np.random.default_rng(0)
    random_direction = jnp.asarray(rng.choice([-1.0, 1.0], case.n_design) / np.sqrt(case.n_design))

    def psi_fn(rtol, solver=None):
        return eqx.filter_jit(lambda x: ffr_jax.objective(case, x, rtol=rtol, atol=rtol * 1e-2, solver=solver))

    reference_psi = psi_fn(1e-12)
    # Backward tolerances of the adjoint and backsolve: rtol 1e-10 and atol 1e-16 (the adjoint
    # states are of the size of psi, ~1e-7 on this case: tests/test_sensitivity.py).
    back = dict(rtol=1e-10, atol=1e-16)
    configs = [
        ("autodiff", "dopri8", 1e-10, ffr_jax.Autodiff(), None),
        ("autodiff", "dopri8", 1e-12, ffr_jax.Autodiff(), None),
        ("adjoint", "dopri8", 1e-10, ffr_jax.Adjoint(**back), None),
        ("backsolve", "dopri8", 1e-10, ffr_jax.Backsolve(**back), None),
        ("autodiff", "rodas5p", 1e-10, ffr_jax.Autodiff(), Rodas5P()),
        ("adjoint", "rodas5p", 1e-10, ffr_jax.Adjoint(**back), Rodas5P()),
        ("backsolve", "rodas5p", 1e-10, ffr_jax.Backsolve(**back), Rodas5P()),
        ("discrete-adjoint", "rodas5p", 1e-10, ffr_jax.DiscreteAdjoint(), Rodas5P()),
    ]
    if args.only:
        configs = [c for c in configs if f"{c[0]}:{c[1]}:{c[2]:g}" in args.only]
    rows, grads = [], []
    for name, solver_name, rtol, method, solver in configs:
        fn = eqx.filter_jit(lambda x, method=method, rtol=rtol, solver=solver: ffr_jax.value_and_grad(
            case, x, method, rtol=rtol, atol=rtol * 1e-2, solver=solver))
        start = time.perf_counter()
        jax.block_until_ready(fn(x))
        first = time.perf_counter() - start
        run_s, (psi, grad) = timed(fn, x, runs=args.runs)
        grads.append(np.asarray(grad))
        own_psi = psi_fn(rtol, solver)
        forward_s, _ = timed(own_psi, x, runs=args.runs)
        unit = grad / jnp.linalg.norm(grad)
        row = {"method": name, "solver": solver_name, "rtol": rtol, "psi": float(psi), "compile_s": first - run_s,
               "run_s": run_s, "forward_s": forward_s, "max_abs_grad": float(jnp.max(jnp.abs(grad))),
               "grad_head": np.asarray(grad[:4]).tolist()}
        start = time.perf_counter()
        guard = ffr_jax.check_gradient(case, x, grad, rtol=rtol, atol=rtol * 1e-2, solver=solver)
        row["guard"] = {"trusted": guard.trusted, "error": float(guard.error[0]), "s": time.perf_counter() - start}
        for label, d in (("gradient", unit), ("random", random_direction)):
            for step in (1e-4,):
                gd, fd, rel = directional_check(own_psi, x, grad, d, step)
                _, fd_ref, _ = directional_check(reference_psi, x, grad, d, step)
                row[f"{label}_{step:g}"] = {"g.d": gd, "fd_same_solver": fd, "rel_same_solver": rel,
                                            "fd_reference": fd_ref,
                                            "rel_reference": abs(gd - fd_ref) / max(abs(gd), abs(fd_ref), 1e-300)}
        row["guard_cost_over_gradient"] = 2 * forward_s / run_s
        # The process's peak so far (rows run in order, so a row's own peak is at most this).
        row["peak_rss_mb_so_far"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        row["load"] = os.getloadavg()
        rows.append(row)
        print(json.dumps(row), flush=True)
        # Written after every row, so that a run stopped part-way keeps what it measured.
        out = pathlib.Path(args.out)
        out.parent.mkdir(exist_ok=True)
        out.write_text(json.dumps({"modes": args.modes, "rows": rows, "complete": False}, indent=1))
    # Reference gradient: the central differences of psi at rtol 1e-12 (Dopri8) along each gradient's
    # own direction are in the rows; the gradients are also compared with each other here.
    for row, grad in zip(rows, grads):
        row["grad_rel_difference_to"] = {
            f"{other['method']}:{other['solver']}:{other['rtol']:g}": float(np.max(np.abs(grad - g)) / np.max(np.abs(g)))
            for other, g in zip(rows, grads)}
    out = pathlib.Path(args.out)
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"modes": args.modes, "rows": rows, "complete": True}, indent=1))


if __name__ == "__main__":
    main()
