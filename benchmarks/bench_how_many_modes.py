"""How many modes? psi and its design gradient against retained modes, with the cost of each (issue 15).

For each mode count N: `fj.cases.slider_crank(nx, ny, N, t1)` at the uniform design x = 0.5, psi and
the gradient by autodiff through Rodas5P (`fj.Rodas5P()`, rtol 1e-10, atol 1e-12): the route that at
20 modes agrees with the Dopri8 adjoint, backsolve and finite differences to ~2e-8 and costs a fraction
of them (RESULTS.md, "Every method at 20 modes against finite differences"), and whose step count does
not grow with the highest retained frequency. Errors are relative to the `--reference` mode count: psi
`|psi_N - psi_ref| / psi_ref`, the gradient `max |g_N - g_ref| / max |g_ref|` (max norm).
Compile = first call minus one run; run = one further call (single samples). Each row is written to
`results/<out>.json` as it finishes (a stopped run keeps what it measured); at the end a table and a
figure (`results/<out>.png`) go to RESULTS.md, section "How many modes".

Usage: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/bench_how_many_modes.py
[--mesh 12 2 0.2] [--modes 2 4 6 8 10 15 20 30] [--reference 40]`
"""

import argparse
import json
import os
import pathlib
import sys
import time

import equinox as eqx
import jax
import numpy as np

import ffr_jax as fj

HERE = pathlib.Path(__file__).parent
sys.path.insert(0, str(HERE))
from _results import machine, write_section  # noqa: E402


def row_for(nx, ny, t1, n_modes, rtol, method):
    case = fj.cases.slider_crank(nx, ny, n_modes, t1)
    x = jax.numpy.asarray(np.full(case.n_design, 0.5))
    solver = fj.Rodas5P()
    gradient = eqx.filter_jit(lambda x: fj.value_and_grad(case, x, method, rtol=rtol, atol=rtol * 1e-2, solver=solver))
    forward = eqx.filter_jit(lambda x: fj.objective(case, x, rtol=rtol, atol=rtol * 1e-2, solver=solver))
    start = time.perf_counter()
    jax.block_until_ready(gradient(x))
    first = time.perf_counter() - start
    start = time.perf_counter()
    psi, grad = jax.block_until_ready(gradient(x))
    run = time.perf_counter() - start
    jax.block_until_ready(forward(x))
    start = time.perf_counter()
    jax.block_until_ready(forward(x))
    forward_s = time.perf_counter() - start
    return dict(modes=n_modes, psi=float(psi), grad=np.asarray(grad).tolist(), compile_s=first - run, run_s=run,
                forward_s=forward_s, highest_hz=float(case.frequencies(x)[-1]), load=os.getloadavg())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", nargs=3, type=float, default=[12, 2, 0.2], metavar=("NX", "NY", "T1"))
    parser.add_argument("--modes", nargs="+", type=int, default=[2, 4, 6, 8, 10, 15, 20, 30])
    parser.add_argument("--reference", type=int, default=40)
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--method", default="autodiff",
                        help="gradient method through Rodas5P: autodiff (the 12 x 2 study) or adjoint (the paper's, "
                             "backward on the forward's steps; backward tolerances rtol 1e-8 / atol 1e-10)")
    parser.add_argument("--section", default="How many modes", help="title of the RESULTS.md section")
    parser.add_argument("--out", default="how_many_modes")
    parser.add_argument("--from-json", action="store_true",
                        help="no computation: figure and section from results/<out>.json (e.g. after replacing a row)")
    parser.add_argument("--no-write", action="store_true", help="do not write the RESULTS.md section (smoke runs)")
    args = parser.parse_args()
    nx, ny, t1 = int(args.mesh[0]), int(args.mesh[1]), args.mesh[2]
    path = HERE / "results" / f"{args.out}.json"
    path.parent.mkdir(exist_ok=True)
    if args.from_json:  # re-write the figure and the section from the saved rows
        rows = json.loads(path.read_text())["rows"]
    else:
        rows = measure(args, nx, ny, t1, path)
    report(args, rows, nx, ny, t1)


def measure(args, nx, ny, t1, path):
    rows = []
    for n in [args.reference, *args.modes]:  # the reference first: every later row is compared as it comes
        row = row_for(nx, ny, t1, n, args.rtol, args.method)
        if rows:
            ref = rows[0]
            g, g_ref = np.asarray(row["grad"]), np.asarray(ref["grad"])
            row["psi_error"] = abs(row["psi"] - ref["psi"]) / abs(ref["psi"])
            row["grad_error"] = float(np.max(np.abs(g - g_ref)) / np.max(np.abs(g_ref)))
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "grad"}), flush=True)
        path.write_text(json.dumps(dict(mesh=[nx, ny, t1], rtol=args.rtol, reference=args.reference, rows=rows,
                                        complete=False)))
    path.write_text(json.dumps(dict(mesh=[nx, ny, t1], rtol=args.rtol, reference=args.reference, rows=rows,
                                    complete=True)))

    return rows


def report(args, rows, nx, ny, t1):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    body_rows = sorted(rows[1:], key=lambda r: r["modes"])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    modes = [r["modes"] for r in body_rows]
    ax1.semilogy(modes, [max(r["psi_error"], 1e-16) for r in body_rows], "o-", label="psi")
    ax1.semilogy(modes, [max(r["grad_error"], 1e-16) for r in body_rows], "s-", label="gradient (max norm)")
    ax1.set_xlabel("retained modes"), ax1.set_ylabel(f"relative error vs {args.reference} modes"), ax1.legend()
    ax2.plot(modes, [r["run_s"] for r in body_rows], "o-", label="gradient run")
    ax2.plot(modes, [r["forward_s"] for r in body_rows], "s-", label="forward run")
    ax2.set_xlabel("retained modes"), ax2.set_ylabel("seconds (after compilation)"), ax2.legend()
    fig.suptitle(f"slider_crank({nx}, {ny}, N, {t1:g}), x = 0.5, {args.method} through Rodas5P, rtol {args.rtol:g}")
    fig.tight_layout()
    fig.savefig(HERE / "results" / f"{args.out}.png", dpi=110)

    lines = [f"| {r['modes']} | {r['highest_hz']:.0f} | {r['psi']:.10e} | {r['psi_error']:.1e} | {r['grad_error']:.1e} | "
             f"{r['compile_s']:.1f} | {r['run_s']:.2f} | {r['forward_s']:.3f} |" for r in body_rows]
    ref = rows[0]
    body = "\n".join([
        f"Command: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/bench_how_many_modes.py --mesh {nx} {ny} {t1:g} "
        f"--modes {' '.join(map(str, args.modes))} --reference {args.reference} --method {args.method} --rtol {args.rtol:g} "
        f"--out {args.out} --section '{args.section}'`. Raw rows: `benchmarks/results/{args.out}.json`; "
        f"figure `benchmarks/results/{args.out}.png`.",
        "",
        f"`fj.cases.slider_crank({nx}, {ny}, N, {t1:g})` at x = 0.5; psi and gradient by {args.method} through `fj.Rodas5P()` at rtol "
        f"{args.rtol:g}; errors relative to N = {args.reference} (psi {ref['psi']:.10e}, highest retained frequency "
        f"{ref['highest_hz']:.0f} Hz, gradient run {ref['run_s']:.2f} s, compile {ref['compile_s']:.1f} s). Single samples.",
        "",
        "| modes | highest retained [Hz] | psi | psi rel. error | gradient rel. error (max norm) | compile [s] | gradient run [s] | forward [s] |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
        *lines,
        "",
        f"Machine: {machine()}.",
    ])
    if not args.no_write:
        write_section(args.section, body)


if __name__ == "__main__":
    main()
