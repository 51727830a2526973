"""The default route's gradient call (discrete adjoint of Rodas5P, rtol 1e-7, atol 1e-9) on the reference case,
written with names that exist at every commit since 24 Nov, so that two commits can be timed on the same machine.

    git worktree add /tmp/wt b13b4b6
    PYTHONPATH=/tmp/wt taskset -c 0 python benchmarks/bench_route_between_commits.py --tag b13b4b6
    taskset -c 0 python benchmarks/bench_route_between_commits.py --tag HEAD

Prints the compile time (`lower` + `compile`) and the median of five later calls at other designs (each a new
design, so no call is served from a cache), with psi and max |grad| to check both commits compute the same.
"""

import argparse
import statistics
import time

import equinox as eqx
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import ffr_jax  # noqa: E402

try:  # the solver's home moved with the package's restructuring (issue 29)
    from ffr_jax._solver import Rodas5P
except ImportError:
    from ffr_jax import Rodas5P


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tag", default="", help="a label for the printed line (e.g. the commit)")
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    case = ffr_jax.cases.slider_crank(n_modes=6)
    x = case.initial_design(0.5)
    method = ffr_jax.DiscreteAdjoint()

    @eqx.filter_jit
    def gradient(x):
        return ffr_jax.value_and_grad(case, x, method, rtol=1e-7, atol=1e-9, solver=Rodas5P())

    start = time.perf_counter()
    compiled = gradient.lower(x).compile()
    compile_s = time.perf_counter() - start
    psi, grad = jax.block_until_ready(compiled(x))
    samples = []
    for k in range(args.runs):
        start = time.perf_counter()
        jax.block_until_ready(compiled(x * (1.0 - 0.01 * (k + 1))))
        samples.append(time.perf_counter() - start)
    print(f"{args.tag}: compile {compile_s:.1f} s, gradient median {statistics.median(samples):.3f} s "
          f"(runs {' '.join(f'{s:.3f}' for s in samples)}), psi {float(psi):.10e}, "
          f"max |grad| {float(np.max(np.abs(grad))):.4e}")


if __name__ == "__main__":
    main()
