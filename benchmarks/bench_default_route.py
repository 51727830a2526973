"""The default route of `fj.value_and_grad(case, x)` on the reference case at 6, 15 and 30 modes (issue 28).

Each mode count runs in its own fresh process (no persistent compilation cache): the first call of
`fj.value_and_grad(case, x)` with no options (compile and run, split into tracing, lowering and XLA
by `jax.monitoring`), then the median of three calls at other designs of the same shape; one forward
solve on the same route (`fj.objective` with the route's solver and tolerances, median of three after
its own compile); psi and the gradient against the tight references kept in benchmarks/results
(6 modes: the Dopri8 adjoint at rtol 1e-12; 15: the adjoint through Rodas5P at 1e-12; 30: the
discrete adjoint at 1e-12; benchmarks/RESULTS.md, "The discrete adjoint of Rodas5P ...").

    python benchmarks/bench_default_route.py            # all rows, then writes the RESULTS section
    python benchmarks/bench_default_route.py --row 6    # one row (what the driver runs per process)
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).parent
REFERENCES = {6: "stiff_gradient_ref_6_adjoint_dopri8_1e-12.npz", 15: "stiff_gradient_ref_15_adjoint_rodas5p_1e-12.npz",
              30: "stiff_gradient_ref_30_discrete_rodas5p_1e-12.npz"}


def row(modes: int) -> dict:
    import jax
    import jax.monitoring as monitoring
    import numpy as np

    durations: dict[str, float] = {}

    def listen(event, duration, **kwargs):
        durations[event] = durations.get(event, 0.0) + duration

    monitoring.register_event_duration_secs_listener(listen)
    import ffr_jax as fj

    case = fj.cases.slider_crank(n_modes=modes)
    x = case.initial_design(0.5)
    route = fj.choose_route(case)
    start = time.perf_counter()
    psi, grad = jax.block_until_ready(fj.value_and_grad(case, x))
    first = time.perf_counter() - start
    split = {name: durations.get(f"/jax/core/compile/{event}", 0.0) for name, event in
             (("trace", "jaxpr_trace_duration"), ("lower", "jaxpr_to_mlir_module_duration"),
              ("xla", "backend_compile_duration"))}
    later = []
    for k in range(3):
        start = time.perf_counter()
        jax.block_until_ready(fj.value_and_grad(case, x * (0.99 - 0.01 * k)))
        later.append(time.perf_counter() - start)

    def forward(design):
        return fj.objective(case, design, solver=route.solver, rtol=route.rtol, atol=route.atol)

    jax.block_until_ready(forward(x))
    forwards = []
    for k in range(3):
        start = time.perf_counter()
        jax.block_until_ready(forward(x * (0.99 - 0.01 * k)))
        forwards.append(time.perf_counter() - start)
    # `fj.objective(case, x)` with no options (Dopri8, rtol 1e-10): the forward solve a user meets first, the one
    # the "at most 3x one forward solve" was measured against.
    jax.block_until_ready(fj.objective(case, x))
    plain = []
    for k in range(3):
        start = time.perf_counter()
        jax.block_until_ready(fj.objective(case, x * (0.99 - 0.01 * k)))
        plain.append(time.perf_counter() - start)
    reference = np.load(HERE / "results" / REFERENCES[modes])
    g = np.asarray(grad)
    return dict(modes=modes, route=route.reason, first=first, **split, gradient=statistics.median(later),
                forward=statistics.median(forwards), plain_forward=statistics.median(plain),
                psi_error=abs(float(psi) - float(reference["psi"])) / abs(float(reference["psi"])),
                grad_error=float(np.max(np.abs(g - reference["grad"])) / np.max(np.abs(reference["grad"]))),
                load=os.getloadavg()[0])


def _fresh_row(modes: int, xla_flags: str | None = None) -> dict:
    """One row in a fresh process with an empty cache folder (`xla_flags`: added to XLA_FLAGS)."""
    env = {**os.environ, "JAX_ENABLE_COMPILATION_CACHE": "false", "FFR_JAX_CACHE_DIR": tempfile.mkdtemp()}
    if xla_flags:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {xla_flags}".strip()
    out = subprocess.run([sys.executable, __file__, "--row", str(modes)], capture_output=True, text=True, check=True,
                         env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--row", type=int)
    parser.add_argument("--modes", type=int, nargs="+", default=[6, 15, 30])
    parser.add_argument("--scheduler-too", action="store_true",
                        help="also run each row with XLA's CPU concurrency-optimised scheduler on (XLA_FLAGS), as the "
                             "package's programs were compiled before they turned it off")
    args = parser.parse_args()
    if args.row is not None:
        print(json.dumps(row(args.row)))
        return
    rows = []
    for modes in args.modes:
        rows.append(_fresh_row(modes))
        print(rows[-1], flush=True)
        if args.scheduler_too:
            rows[-1]["scheduler_on"] = _fresh_row(modes, "--xla_cpu_enable_concurrency_optimized_scheduler=true")
            print(rows[-1]["scheduler_on"], flush=True)
    sys.path.insert(0, str(HERE))
    from _results import machine, write_section

    six = next((r for r in rows if r["modes"] == 6), None)
    lines = [
        "Command: `python benchmarks/bench_default_route.py` (each row in a fresh process, no persistent compilation",
        f"cache). Machine: {machine()}; default XLA settings and threading.",
        "",
        "`fj.value_and_grad(case, x)` with no options on `fj.cases.slider_crank(n_modes=m)` at x = 0.5: the route it",
        "took (`fj.choose_route`), its first call (compile and run; tracing, lowering and XLA from `jax.monitoring`),",
        "the median of three later calls at other designs, one forward solve on the same route (`fj.objective` with",
        "the route's solver and tolerances, median of three), the plain forward solve `fj.objective(case, x)` (Dopri8",
        "at rtol 1e-10, median of three), and psi and the gradient (max norm) against tight",
        "references (6 modes: Dopri8 adjoint at rtol 1e-12; 15: adjoint through Rodas5P at 1e-12; 30: the discrete",
        "adjoint at 1e-12).",
        "",
        "| modes | route | first call [s] | trace / lower / XLA [s] | gradient [s] | forward on the route [s] |"
        " gradient / forward | plain `fj.objective` [s] | gradient / plain | 30 or 15 / 6 modes | psi error |"
        " gradient error | load |",
        "|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        against_six = f"{r['gradient'] / six['gradient']:.2f}x" if six and r is not six else "—"
        lines.append(
            f"| {r['modes']} | {r['route'].split(':')[0]}: {r['route'].split(': ', 1)[1].split(' (')[0]} | "
            f"{r['first']:.1f} | {r['trace']:.1f} / {r['lower']:.1f} / {r['xla']:.1f} | {r['gradient']:.3f} | "
            f"{r['forward']:.3f} | {r['gradient'] / r['forward']:.1f} | {r['plain_forward']:.3f} | "
            f"{r['gradient'] / r['plain_forward']:.1f} | {against_six} | {r['psi_error']:.1e} | "
            f"{r['grad_error']:.1e} | {r['load']:.1f} |")
    on = [r for r in rows if "scheduler_on" in r]
    if on:
        lines += ["", "The package compiles its programs with XLA's CPU concurrency-optimised scheduler off "
                  "(`ffr_jax/_dynamics/_xla_flags.py`, `program_options`). The same rows, each in another fresh process "
                  "with `XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=true` (the programs as compiled "
                  "before, when only the `ffr-jax` command turned it off):", "",
                  "| modes | gradient, scheduler off (default) [s] | gradient, scheduler on [s] | on / off | forward off / on [s] |"
                  " first call off / on [s] | load |", "|---:|---:|---:|---:|---|---|---|"]
        for r in on:
            o = r["scheduler_on"]
            lines.append(f"| {r['modes']} | {r['gradient']:.3f} | {o['gradient']:.3f} | {o['gradient'] / r['gradient']:.2f} | "
                         f"{r['forward']:.3f} / {o['forward']:.3f} | {r['first']:.1f} / {o['first']:.1f} | "
                         f"{r['load']:.1f} / {o['load']:.1f} |")
    lines += ["", "Why each route (the log line, `fj.choose_route(case).reason`):", ""]
    lines += [f"- {r['modes']} modes: {r['route']}" for r in rows]
    write_section("Default route", "\n".join(lines))


if __name__ == "__main__":
    main()
