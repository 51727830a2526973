"""Run the gradient guard (`ffr_jax.check_gradient`) on gradients saved by `bench_stiff_gradient.py` (issue 15).

Each `--gradients` entry is `PATH:SOLVER:RTOL`: a `.npz` under `benchmarks/results/` with the gradient `grad` of
the reference case (`fj.cases.slider_crank(n_modes=--modes)` at x = 0.5), and the forward solver (`dopri8` or
`rodas5p`) and rtol (atol = rtol / 100) the check's two forward solves use, those of the gradient's own solve. Prints,
per gradient, whether the guard trusts it, the directional derivative it predicts along itself against the central
difference of psi, and the check's time.

Usage: `PYTHONPATH=$PWD python benchmarks/check_saved_gradients.py --modes 30 --gradients
modes_cost_dopri8_wp_gradients/30_autodiff_dopri8_1e-06.npz:dopri8:1e-6`
"""

import argparse
import pathlib
import time

import diffrax
import numpy as np

import ffr_jax as fj

RESULTS = pathlib.Path(__file__).parent / "results"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, required=True)
    parser.add_argument("--gradients", nargs="+", required=True, metavar="PATH:SOLVER:RTOL")
    args = parser.parse_args()
    case = fj.cases.slider_crank(n_modes=args.modes)
    x = case.initial_design(0.5)
    print("| gradient | solver | rtol | trusted | directional derivative | central difference | relative difference | check [s] |")
    print("|---|---|---:|---|---:|---:|---:|---:|")
    for entry in args.gradients:
        path, solver_name, rtol = entry.rsplit(":", 2)
        solver = {"dopri8": diffrax.Dopri8(), "rodas5p": fj.Rodas5P()}[solver_name]
        rtol = float(rtol)
        grad = np.load(RESULTS / path)["grad"]
        start = time.perf_counter()
        check = fj.check_gradient(case, x, grad, rtol=rtol, atol=rtol * 1e-2, solver=solver)
        seconds = time.perf_counter() - start
        print(f"| {path} | {solver_name} | {rtol:g} | {bool(check.trusted)} | {float(check.directional[0]):.6e} | "
              f"{float(check.finite_difference[0]):.6e} | {float(check.error[0]):.1e} | {seconds:.1f} |")


if __name__ == "__main__":
    main()
