"""Work–precision on the reference case itself (issue 6): error of psi and of the 588-entry gradient
against a tight reference versus run time, for the gradient methods that run at this size in
seconds (adjoint, autodiff, backsolve) x Tsit5, Dopri8 x forward rtol 1e-6, 1e-8, 1e-10 (atol =
1e-2 rtol; adjoint and backsolve backward tolerances = the forward ones). The direct method (one
forward-mode tangent per scene parameter, ~1 min per gradient) and finite differences (1,177
solves, ~17 min per gradient) are in the reduced-case study of bench_work_precision.py and in the
timing table of bench_gradient.py.

Reference: autodiff with Dopri8 at rtol 1e-12 / atol 1e-14. Each configuration is compiled once
(`jit(...).lower(x).compile()`, timed separately) and run `--repeats` times (median).

Usage: `python benchmarks/bench_wp_reference.py [--repeats 2]`. Writes
`benchmarks/results/wp_reference.{json,md,png}` and the section "Work–precision on the reference case"
of `benchmarks/RESULTS.md`.
"""

import argparse
import json
import pathlib
import statistics
import sys
import time

import diffrax
import jax
import numpy as np

import ffr_jax as fj

HERE = pathlib.Path(__file__).parent
TITLE = "Work–precision on the reference case (bench_wp_reference.py)"
SOLVERS = {"Tsit5": diffrax.Tsit5, "Dopri8": diffrax.Dopri8}


def _method(name, rtol, atol):
    if name == "adjoint":
        return fj.Adjoint(rtol=rtol, atol=atol)
    if name == "backsolve":
        return fj.Backsolve(rtol=rtol, atol=atol)
    return name


def measure(case, x, method, solver, rtol, atol, repeats):
    fn = jax.jit(lambda x: fj.value_and_grad(case, x, _method(method, rtol, atol), rtol=rtol, atol=atol,
                                             solver=solver))
    start = time.perf_counter()
    compiled = fn.lower(x).compile()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        psi, grad = jax.block_until_ready(compiled(x))
        times.append(time.perf_counter() - start)
    return float(psi), np.asarray(grad), compile_s, statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--rtols", nargs="+", type=float, default=[1e-6, 1e-8, 1e-10])
    parser.add_argument("--methods", nargs="+", default=["adjoint", "autodiff", "backsolve"])
    args = parser.parse_args()

    case = fj.cases.slider_crank()
    x = case.initial_design(0.5)
    psi_ref, g_ref, ref_compile, ref_run = measure(case, x, "autodiff", diffrax.Dopri8(), 1e-12, 1e-14, 1)
    print(f"reference: psi {psi_ref:.12e}, compile {ref_compile:.1f} s, run {ref_run:.2f} s", flush=True)
    rows = []
    for method in args.methods:
        for solver_name, solver in SOLVERS.items():
            for rtol in args.rtols:
                psi, g, c, r = measure(case, x, method, solver(), rtol, 1e-2 * rtol, args.repeats)
                row = {"method": method, "solver": solver_name, "rtol": rtol, "psi_error": abs(psi - psi_ref) / psi_ref,
                       "grad_error": float(np.abs(g - g_ref).max() / np.abs(g_ref).max()), "compile_s": c, "run_s": r}
                rows.append(row)
                print(json.dumps(row), flush=True)

    out = HERE / "results"
    out.mkdir(exist_ok=True)
    (out / "wp_reference.json").write_text(json.dumps({"psi_ref": psi_ref, "rows": rows}, indent=1))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for k, method in enumerate(args.methods):
        for solver_name, style in (("Tsit5", "o--"), ("Dopri8", "s-")):
            sel = [r for r in rows if r["method"] == method and r["solver"] == solver_name]
            ax.loglog([r["run_s"] for r in sel], [max(r["grad_error"], 1e-16) for r in sel], style, color=f"C{k}",
                      label=f"{method}, {solver_name}")
    ax.set_xlabel("run time after compilation [s]")
    ax.set_ylabel("max |grad - grad_ref| / max |grad_ref|")
    ax.set_title("Reference case (588 densities): gradient work–precision")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "wp_reference.png", dpi=120)

    sys.path.insert(0, str(HERE))
    from _results import machine, write_section

    lines = [
        f"Command: `python benchmarks/bench_wp_reference.py --repeats {args.repeats}`. Reference case (100 x 6, 588 "
        f"densities, 6 modes, t1 = 3 s, x = 0.5, sparse FE path). Errors against autodiff with Dopri8 at rtol 1e-12 / "
        f"atol 1e-14 (psi_ref = {psi_ref:.12e}); atol = 1e-2 rtol; the adjoint's and backsolve's backward "
        f"tolerances equal the forward ones. Run time: median of {args.repeats} after ahead-of-time compilation.",
        f"Machine: {machine()}.",
        "",
        "| method | solver | rtol | psi rel. error | grad rel. error (max norm) | run [s] | compile [s] |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['method']} | {r['solver']} | {r['rtol']:.0e} | {r['psi_error']:.1e} | {r['grad_error']:.1e} | "
                     f"{r['run_s']:.2f} | {r['compile_s']:.1f} |")
    lines += ["", "Figure: `benchmarks/results/wp_reference.png`; numbers: `benchmarks/results/wp_reference.json`. "
              "Direct and finite differences: reduced case below and `bench_gradient.py`."]
    text = "\n".join(lines)
    (out / "wp_reference.md").write_text(text + "\n")
    write_section(TITLE, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
