"""One table of gradient cost and accuracy against retained modes on the reference case, from the rows of
`bench_stiff_gradient.py` (issue 15), with the errors recomputed against a reference of choice.

`bench_stiff_gradient.py` compares every row with the reference it was given when it ran and saves each
row's psi and gradient (`results/<out>_gradients/`). This script reads those rows (`--runs`, the `<out>`
names), recomputes the psi and gradient errors against `--reference MODES=PATH.npz` (files with `psi` and
`grad`), and writes the RESULTS.md section `--section`: one table of every row, one of the 30 / 6 modes
ratios of forward and gradient run time per method and tolerance.

Usage (the command of the RESULTS section is printed in it): `python benchmarks/modes_cost_summary.py --runs
modes_cost_wp modes_cost_mid modes_cost_dopri8 modes_cost_backsolve --reference
6=benchmarks/results/stiff_gradient_ref_6_adjoint_dopri8_1e-12.npz 30=... --figure modes_cost_work_precision
--section "Cost against retained modes on the reference case (issue 15)" --intro "..."`
"""

import argparse
import json
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE))
from _results import write_section  # noqa: E402


def rows_of(run):
    data = json.loads((RESULTS / f"{run}.json").read_text())
    for row in data["rows"]:
        row["run_name"] = run
        row["command"] = data["command"]
        yield row


def gradient_file(row):
    name = f"{row['modes']}_{row['method'].replace(':', '_')}_{row['rtol']:g}.npz"
    return RESULTS / f"{row['run_name']}_gradients" / name


def figure(done, name, modes_list):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(modes_list), figsize=(5.5 * len(modes_list), 4.2), layout="constrained")
    for ax, modes in zip(np.atleast_1d(axes), modes_list):
        methods = sorted({m for (n, m, _) in done if n == modes})
        for method in methods:
            pts = sorted((r["run_s"], r["grad_error_vs_reference"], rtol) for (n, m, rtol), r in done.items()
                         if n == modes and m == method)
            ax.loglog([p[0] for p in pts], [max(p[1], 1e-14) for p in pts], "o-", label=method)
            for run, err, rtol in pts:
                ax.annotate(f"{rtol:g}", (run, max(err, 1e-14)), fontsize=7, textcoords="offset points", xytext=(3, 3))
        ax.set_title(f"reference case, {modes} modes"), ax.set_xlabel("gradient run time [s]")
        ax.set_ylabel("gradient error (max norm, relative)"), ax.legend(fontsize=8)
    fig.savefig(RESULTS / f"{name}.png", dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", required=True)
    parser.add_argument("--reference", nargs="+", default=[], metavar="MODES=PATH")
    parser.add_argument("--reference-note", default="", help="what the references are (printed above the table)")
    parser.add_argument("--section", default="Cost against retained modes on the reference case")
    parser.add_argument("--intro", default="", help="a paragraph for the top of the section")
    parser.add_argument("--figure", default=None, help="write a work-precision figure (gradient error vs run time, "
                        "one panel per mode count in --figure-modes) to results/<figure>.png")
    parser.add_argument("--figure-modes", type=int, nargs="+", default=[6, 30])
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    refs = {}
    for item in args.reference:
        modes, path = item.split("=", 1)
        data = np.load(path)
        refs[int(modes)] = (float(data["psi"]), np.asarray(data["grad"]), path)
    rows = [r for run in args.runs for r in rows_of(run)]
    rows.sort(key=lambda r: (r["modes"], r["method"], r["rtol"]))
    lines = ["| modes | method:solver | rtol | compile [s] | run [s] | forward [s] (steps) | run / forward | "
             "psi rel. error | grad rel. error (max norm) | peak RSS [MB] | load (1 min) |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    done = {}
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['modes']} | {r['method']} | {r['rtol']:g} | {r['error']} | | | | | | | |")
            continue
        psi_err, grad_err = r["psi_rel_error"], r["grad_rel_error"]
        if r["modes"] in refs and gradient_file(r).exists():
            psi_ref, grad_ref, _ = refs[r["modes"]]
            saved = np.load(gradient_file(r))
            psi_err = abs(float(saved["psi"]) - psi_ref) / abs(psi_ref)
            grad_err = float(np.max(np.abs(saved["grad"] - grad_ref)) / np.max(np.abs(grad_ref)))
        done[(r["modes"], r["method"], r["rtol"])] = r
        r["grad_error_vs_reference"] = grad_err
        lines.append(f"| {r['modes']} | {r['method']} | {r['rtol']:g} | {r['compile_s']:.1f} | {r['run_s']:.3f} | "
                     f"{r['forward_s']:.3f} ({r['forward_steps']}) | {r['run_s'] / r['forward_s']:.2f} | "
                     f"{psi_err:.1e} | {grad_err:.1e} | {r['peak_rss_mb']:.0f} | {r['load'][0]:.2f} |")
    ratios = ["| method:solver | rtol | forward 30 / 6 modes | gradient 30 / 6 modes |", "|---|---:|---:|---:|"]
    for (modes, method, rtol), r in sorted(done.items()):
        low = done.get((6, method, rtol))
        if modes == 30 and low is not None:
            ratios.append(f"| {method} | {rtol:g} | {r['forward_s'] / low['forward_s']:.2f} | "
                          f"{r['run_s'] / low['run_s']:.2f} |")
    if args.figure:
        figure(done, args.figure, args.figure_modes)
        ratios += ["", f"Work–precision figure: `benchmarks/results/{args.figure}.png` (gradient error against run time "
                       f"after compilation, {', '.join(map(str, args.figure_modes))} modes)."]
    commands = sorted({f"`{r['command']}`" for r in rows})
    ref_lines = [f"- {m} modes: `{p}`" for m, (_, _, p) in sorted(refs.items())]
    body = "\n".join([
        args.intro, "",
        "Commands (each row in its own process, `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock` before each):",
        *[f"- {c}" for c in commands], "",
        f"Summary: `python benchmarks/modes_cost_summary.py --runs {' '.join(args.runs)} --reference "
        f"{' '.join(args.reference)}`. Errors recomputed against:", *ref_lines, args.reference_note, "",
        *lines, "", *ratios, ""])
    print(body)
    if not args.no_write:
        write_section(args.section, body)


if __name__ == "__main__":
    main()
