"""Benchmark the foundation of the design pipeline on the reference rod (REFERENCE_CASE §1–2).

Stages, each jitted as a function of the design `x` (588 variables at `x = 0.5`):

1. FE assembly `x -> (K, M)`;
2. assembly + modal reduction `x -> (omega^2, Phi)`;
3. assembly + modal reduction + body data `x -> BodyData` (the forward map);
4. its VJP: `x -> grad trace(Phi^T K Phi)`, a span-invariant scalar of the body data.

For each: compile time (`jit(...).lower(x).compile()`) and the median of several runs of the compiled
function with `block_until_ready`; ratios are to the forward map, measured in the same run.

Usage: `python benchmarks/bench_fe.py [--nx 100 --ny 6 --modes 6 --runs 7]`. On a shared CPU, XLA's
multi-threaded LAPACK calls (the eigen-solver) can stall for seconds when other processes compete for
the cores; `XLA_FLAGS=--xla_cpu_multi_thread_eigen=false` gives stable timings there.
"""

import argparse
import os
import pathlib
import platform
import statistics
import time

import jax
import jax.numpy as jnp

import ffr_jax


def _time(f, x, runs):
    """Compile time, median and fastest run time (seconds) of `jit(f)` at `x`."""
    start = time.perf_counter()
    compiled = jax.jit(f).lower(x).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(x))  # warm-up: first-run allocations
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        jax.block_until_ready(compiled(x))
        samples.append(time.perf_counter() - start)
    return compile_s, statistics.median(samples), min(samples)


def _lanczos(case) -> bool:
    """Whether the case's rod takes the Lanczos modal solver."""
    solver = case.design.reduction.solver
    if isinstance(solver, ffr_jax.AutoModes):
        solver = solver.choose(case.design.model)
    return isinstance(solver, ffr_jax.LanczosModes)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=100)
    parser.add_argument("--ny", type=int, default=6)
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path(__file__).parent / "results" / "fe.md")
    args = parser.parse_args()

    start = time.perf_counter()
    case = ffr_jax.cases.slider_crank(args.nx, args.ny, args.modes)
    build_s = time.perf_counter() - start
    x = case.initial_design(0.5)

    def assembly(x):
        return case.design.matrices(x)  # matrix-free K, M (ElementOperator)

    def modal_reduction(x):
        return case.modes(x)

    def body_data(x):
        return case.body_data(x)

    def trace_gradient(x):
        return jax.value_and_grad(lambda x: jnp.trace(case.body_data(x).modal_stiffness))(x)

    stages = [
        ("FE assembly (K, M)", assembly),
        ("assembly + modal reduction", modal_reduction),
        ("assembly + modes + body data (forward)", body_data),
        ("VJP: grad trace(Phi^T K Phi)", trace_gradient),
    ]
    timings = {name: _time(f, x, args.runs) for name, f in stages}
    forward = timings["assembly + modes + body data (forward)"][1]

    device = jax.devices()[0]
    lines = [
        f"# bench_fe: reference rod {args.nx} x {args.ny}, {args.modes} modes, {case.n_design} design variables",
        "",
        f"- device: {device.platform} ({device.device_kind}), {platform.processor() or platform.machine()}, "
        f"jax {jax.__version__}",
        f"- {case.mesh.n_dof} degrees of freedom ({'sparse path: matrix-free K, M, shift-invert Lanczos' if _lanczos(case) else 'dense path'}), design x = 0.5 everywhere",
        f"- median of {args.runs} runs after one warm-up; case construction (not timed below): {build_s:.1f} s",
        f"- load average at the end (1/5/15 min): {', '.join(f'{v:.1f}' for v in os.getloadavg())} "
        f"on {os.cpu_count()} CPUs (shared machines make run times noisy); "
        f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '(unset)')}",
        "",
        "| stage | compile [s] | run, median [ms] | run, fastest [ms] | median / forward median |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, (compile_s, run_s, fastest_s) in timings.items():
        ratio = run_s / forward
        lines.append(f"| {name} | {compile_s:.2f} | {1e3 * run_s:.1f} | {1e3 * fastest_s:.1f} | {ratio:.2f} |")
    table = "\n".join(lines) + "\n"
    print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(table)
    if (args.nx, args.ny, args.modes) == (100, 6, 6):
        from _results import write_section

        command = "python benchmarks/bench_fe.py" + (f" --runs {args.runs}" if args.runs != 7 else "")
        flags = os.environ.get("XLA_FLAGS")
        command = (f"XLA_FLAGS={flags} " if flags else "") + command
        write_section("FE stage: assembly, modal reduction, body data (reference rod)",
                      f"Command: `{command}` (details: `benchmarks/results/fe.md`)\n\n" + "\n".join(lines[2:]) + "\n")


if __name__ == "__main__":
    main()
