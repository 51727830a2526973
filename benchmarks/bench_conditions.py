"""Two crank speeds of the slider-crank: one batched (vmap) evaluation against two separate solves.

The value and the design gradient (adjoint method) of `psi = (psi(8 pi) + psi(12 pi)) / 2`:

- batched: `ffr_jax.OperatingConditions([slow, fast]).value_and_grad(x)` in one compiled program
  (the FE stage and the modal reduction once, the two motions and their adjoints as one vmapped
  solve, one VJP of the design map);
- separate: `ffr_jax.value_and_grad(case, x)` for each speed (one compiled program, called twice:
  the two cases differ only in arrays), summed by the caller.

Compile time is the first call minus the median of later calls; run times are medians over
`--runs` calls after the first, with `block_until_ready`. Also prints the steps each speed takes
(forward), since the batched loop runs until the slower condition is done. Writes
`benchmarks/results/conditions.json`.

Usage: `PYTHONPATH=$PWD python benchmarks/bench_conditions.py [--nx 24 --ny 4 --modes 4 --t1 1.0 --runs 5]`.
"""

import argparse
import json
import os
import pathlib
import platform
import time

import equinox as eqx
import jax
import numpy as np

import ffr_jax as fj

OUT = pathlib.Path(__file__).parent / "results"


def timed(fun, runs):
    """(first call [s], median of `runs` later calls [s], result)."""
    start = time.perf_counter()
    result = jax.block_until_ready(fun())
    first = time.perf_counter() - start
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        jax.block_until_ready(fun())
        times.append(time.perf_counter() - start)
    return first, float(np.median(times)), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=24)
    parser.add_argument("--ny", type=int, default=4)
    parser.add_argument("--modes", type=int, default=4)
    parser.add_argument("--t1", type=float, default=1.0)
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    speeds = (8 * np.pi, 12 * np.pi)
    cases = [fj.cases.slider_crank(args.nx, args.ny, args.modes, args.t1, speed=s) for s in speeds]
    conditions = fj.OperatingConditions(cases)
    x = cases[0].initial_design(0.5)
    kw = dict(rtol=args.rtol, atol=1e-12)

    batched = eqx.filter_jit(lambda c, x: c.value_and_grad(x, "adjoint", **kw))
    b_first, b_run, (value, grad, psis) = timed(lambda: batched(conditions, x), args.runs)

    def separate():
        results = [fj.value_and_grad(c, x, "adjoint", **kw) for c in cases]
        return 0.5 * (results[0][0] + results[1][0]), 0.5 * (results[0][1] + results[1][1])

    s_first, s_run, (value_s, grad_s) = timed(separate, args.runs)
    steps = [int(fj.simulate(c, x, rtol=args.rtol, atol=1e-12).num_steps) for c in cases]
    row = {
        "case": f"slider_crank({args.nx} x {args.ny}, {args.modes} modes, t1 = {args.t1})",
        "speeds": ["8 pi", "12 pi"], "rtol": args.rtol, "psi": [float(p) for p in psis],
        "forward_steps": steps,
        "batched": {"compile_s": b_first - b_run, "run_s": b_run},
        "separate": {"compile_s": s_first - s_run, "run_s": s_run},
        "ratio_run_separate_over_batched": s_run / b_run,
        "agreement_value": float(abs(value - value_s) / abs(value_s)),
        "agreement_grad": float(np.max(np.abs(grad - grad_s)) / np.max(np.abs(grad_s))),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, jax {jax.__version__}, "
                   f"load average {', '.join(f'{v:.1f}' for v in os.getloadavg())}",
        "xla_flags": os.environ.get("XLA_FLAGS", "(default)"),
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "conditions.json").write_text(json.dumps(row, indent=2))
    print(json.dumps(row, indent=2))


if __name__ == "__main__":
    main()
