"""What accuracy costs: work–precision of psi and of its gradient for every method and solver.

Three studies on a member of the slider–crank family (REFERENCE_CASE §5), each configuration in
its own subprocess so that compile time and peak memory (max RSS) are its own:

1. **work–precision**: error of `psi` and of `grad psi` (max norm, relative) against a tight
   reference (adjoint, Dopri8, rtol 1e-12 forward and backward) versus median run time, for
   every gradient method (adjoint, autodiff, backsolve, direct, fd) x solvers (Tsit5, Dopri8) x
   a tolerance sweep. Forward `atol = rtol / 100`; backward solves (adjoint, backsolve) at
   `100 rtol`, `atol = rtol` (the paper's ratio); finite differences with a fixed step of 1e-4.
   The tolerances are traced arrays: one compilation per method and solver serves the sweep.
2. **modes**: forward and adjoint-gradient cost versus the number of retained modes.
3. **scaling**: gradient cost versus the number of design variables (mesh refinement), one
   curve per method, log–log.

Writes `benchmarks/results/work_precision.{json,md,png}`, `modes.png`, `scaling.png` and the
"Work–precision and scaling" section of `benchmarks/RESULTS.md`.

```
flock /tmp/ffr_bench.lock python benchmarks/bench_work_precision.py            # all three studies
flock /tmp/ffr_bench.lock python benchmarks/bench_work_precision.py --study wp --rtols 1e-6 1e-8 1e-10
```
"""

import argparse
import json
import pathlib
import resource
import subprocess
import sys
import time

RESULTS = pathlib.Path(__file__).parent / "results"
SECTION = "## Work–precision and scaling (bench_work_precision.py)"
METHODS = ("adjoint", "autodiff", "backsolve", "direct", "fd")
FD_STEP = 1e-4


# --- worker: one method, one solver, one case, several tolerances -----------------------------------


def worker(spec: dict) -> dict:
    import diffrax
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    import ffr_jax as fj

    nx, ny, n_modes, t1, t_ramp = spec["case"]
    case = fj.cases.slider_crank(nx, ny, n_modes, t1, t_ramp=t_ramp)
    x = case.initial_design(0.5)
    solver = {"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8(), "Kvaerno5": diffrax.Kvaerno5()}[spec["solver"]]
    name = spec["method"]

    def method(rtol):
        if name == "adjoint":
            return fj.Adjoint(rtol=100 * rtol, atol=rtol, solver=solver)
        if name == "backsolve":
            return fj.Backsolve(rtol=100 * rtol, atol=rtol)
        if name == "fd":
            return fj.FiniteDifferences(step=FD_STEP, batch_size=spec.get("fd_batch", 8))
        return {"autodiff": fj.Autodiff, "direct": fj.Direct}[name]()

    if name == "forward":
        @eqx.filter_jit
        def run(rtol):
            return fj.objective(case, x, rtol=rtol, atol=rtol / 100, solver=solver), jnp.zeros(0)
    else:
        @eqx.filter_jit
        def run(rtol):
            return fj.value_and_grad(case, x, method(rtol), rtol=rtol, atol=rtol / 100, solver=solver)

    out = {"spec": spec, "n_design": case.n_design, "rows": []}
    start = time.perf_counter()
    jax.block_until_ready(run(jnp.asarray(spec["rtols"][0])))
    first = time.perf_counter() - start
    for k, rtol in enumerate(spec["rtols"]):
        times = []
        for _ in range(spec["repeats"]):
            start = time.perf_counter()
            psi, grad = jax.block_until_ready(run(jnp.asarray(rtol)))
            times.append(time.perf_counter() - start)
        if k == 0:
            out["compile_s"] = max(first - min(times), 0.0)
        out["rows"].append({"rtol": rtol, "run_s": float(np.median(times)), "psi": float(psi),
                            "grad": np.asarray(grad).tolist()})
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def spawn(spec: dict, timeout: float) -> dict:
    """Run one configuration in a fresh interpreter; a failure or timeout is recorded, not raised."""
    try:
        proc = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)], capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"spec": spec, "error": f"timed out after {timeout:.0f} s"}
    if proc.returncode != 0:
        return {"spec": spec, "error": proc.stderr.strip().splitlines()[-1][:300] if proc.stderr else "failed"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# --- studies ---------------------------------------------------------------------------------------------


def study_work_precision(args, log):
    import numpy as np

    reference = spawn({"case": args.case, "method": "adjoint", "solver": "Dopri8", "rtols": [1e-12], "repeats": 1},
                      args.timeout)
    if "error" in reference:
        raise RuntimeError(f"reference failed: {reference['error']}")
    psi_ref = reference["rows"][0]["psi"]
    g_ref = np.asarray(reference["rows"][0]["grad"])
    log(f"reference psi {psi_ref:.12e}, max|grad| {np.max(np.abs(g_ref)):.3e}")
    runs = []
    for solver in args.solvers:
        for method in ("forward",) + METHODS:
            res = spawn({"case": args.case, "method": method, "solver": solver, "rtols": args.rtols,
                         "repeats": args.repeats}, args.timeout)
            if "error" not in res:
                for row in res["rows"]:
                    row["psi_error"] = abs(row["psi"] - psi_ref) / abs(psi_ref)
                    if method != "forward":
                        g = np.asarray(row.pop("grad"))
                        row["grad_error"] = float(np.max(np.abs(g - g_ref)) / np.max(np.abs(g_ref)))
                    else:
                        row.pop("grad")
            runs.append(res)
            log(f"{solver:7s} {method:9s} " + (res["error"] if "error" in res else
                f"compile {res['compile_s']:.1f} s, peak {res['peak_rss_mb']:.0f} MB, " + ", ".join(
                    f"{r['rtol']:.0e}: {r['run_s']:.3f} s" for r in res["rows"])))
    return {"reference": {"psi": psi_ref, "solver": "Dopri8", "rtol": 1e-12}, "runs": runs}


def study_modes(args, log):
    nx, ny, _, t1, t_ramp = args.case
    runs = []
    for n_modes in args.modes:
        for method in ("forward", "adjoint"):
            res = spawn({"case": [nx, ny, n_modes, t1, t_ramp], "method": method, "solver": "Tsit5",
                         "rtols": [1e-10], "repeats": args.repeats}, args.timeout)
            if "error" not in res:
                res["rows"][0].pop("grad")
            runs.append(res)
            log(f"modes {n_modes:2d} {method:8s} " + (res["error"] if "error" in res else
                f"compile {res['compile_s']:.1f} s, run {res['rows'][0]['run_s']:.3f} s"))
    return runs


def study_scaling(args, log):
    _, _, n_modes, t1, t_ramp = args.case
    runs = []
    for nx, ny in args.meshes:
        for method in ("forward",) + METHODS:
            res = spawn({"case": [nx, ny, n_modes, t1, t_ramp], "method": method, "solver": "Tsit5",
                         "rtols": [1e-10], "repeats": 1, "fd_batch": 16}, args.timeout)
            if "error" not in res:
                res["rows"][0].pop("grad")
            runs.append(res)
            log(f"mesh {nx}x{ny} {method:9s} " + (res["error"] if "error" in res else
                f"n_design {res['n_design']}, compile {res['compile_s']:.1f} s, run {res['rows'][0]['run_s']:.3f} s, "
                f"peak {res['peak_rss_mb']:.0f} MB"))
    return runs


# --- output ----------------------------------------------------------------------------------------------


def plots(data):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if "work_precision" in data:
        fig, axes = plt.subplots(1, 2, figsize=(13, 5), layout="constrained")
        markers = {"Tsit5": "o-", "Dopri8": "s--", "Kvaerno5": "^:"}
        for res in data["work_precision"]["runs"]:
            if "error" in res:
                continue
            s = res["spec"]
            t = [r["run_s"] for r in res["rows"]]
            color = f"C{(('forward',) + METHODS).index(s['method'])}"
            axes[0].loglog(t, [max(r["psi_error"], 1e-16) for r in res["rows"]], markers[s["solver"]],
                           color=color, label=f"{s['method']} {s['solver']}")
            if s["method"] != "forward":
                axes[1].loglog(t, [max(r["grad_error"], 1e-16) for r in res["rows"]], markers[s["solver"]],
                               color=color, label=f"{s['method']} {s['solver']}")
        axes[0].set(xlabel="run time [s] (median, compiled)", ylabel="relative error of psi", title="psi")
        axes[1].set(xlabel="run time [s] (median, compiled)", ylabel="relative max-norm error of grad psi",
                    title="gradient (tolerance sweep along each curve)")
        axes[0].legend(fontsize=7, ncol=2)
        axes[1].legend(fontsize=7, ncol=2)
        fig.savefig(RESULTS / "work_precision.png", dpi=120)
        plt.close(fig)
    if "modes" in data:
        fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
        for method in ("forward", "adjoint"):
            rows = [(r["spec"]["case"][2], r["rows"][0]["run_s"]) for r in data["modes"]
                    if "error" not in r and r["spec"]["method"] == method]
            ax.semilogy(*zip(*rows), "o-", label=method) if rows else None
        ax.set(xlabel="retained modes", ylabel="run time [s]", title="cost vs retained modes (Tsit5, rtol 1e-10)")
        ax.legend()
        fig.savefig(RESULTS / "modes.png", dpi=120)
        plt.close(fig)
    if "scaling" in data:
        fig, ax = plt.subplots(figsize=(6.5, 4.5), layout="constrained")
        for method in ("forward",) + METHODS:
            rows = sorted((r["n_design"], r["rows"][0]["run_s"]) for r in data["scaling"]
                          if "error" not in r and r["spec"]["method"] == method)
            if rows:
                ax.loglog(*zip(*rows), "o-", color=f"C{(('forward',) + METHODS).index(method)}", label=method)
        ax.set(xlabel="design variables", ylabel="run time [s] (compiled)",
               title="gradient cost vs number of design variables")
        ax.legend()
        fig.savefig(RESULTS / "scaling.png", dpi=120)
        plt.close(fig)


def _fmt(value) -> str:
    return "–" if value is None else f"{value:.1e}"


def markdown(data, command, case) -> str:
    nx, ny, n_modes, t1, t_ramp = case
    lines = [SECTION, "", f"Command: `{command}`", "",
             "Timings on a shared 2-core machine (other sessions were running): medians of the runs after "
             "compilation, each configuration in its own process (compile time = first call minus a run; "
             "peak memory = the process's max RSS, JAX and XLA included).", ""]
    if "work_precision" in data:
        wp = data["work_precision"]
        lines += [f"### Work–precision (`slider_crank({nx}, {ny}, n_modes={n_modes}, t1={t1}, t_ramp={t_ramp})`)", "",
                  "A reduced case, not the reference one: finite differences and the direct method on the 588 "
                  "reference variables would take hours per tolerance. Reference: adjoint, Dopri8, rtol 1e-12 "
                  f"(psi = {wp['reference']['psi']:.12e}). Forward atol = rtol/100; adjoint and backsolve "
                  f"backward at 100 rtol; fd step {FD_STEP:g}.", "",
                  "![work-precision](results/work_precision.png)", "",
                  "| solver | method | compile [s] | peak RSS [MB] | rtol | run [s] | psi error | gradient error |",
                  "|---|---|---:|---:|---:|---:|---:|---:|"]
        for res in wp["runs"]:
            s = res["spec"]
            if "error" in res:
                lines.append(f"| {s['solver']} | {s['method']} | – | – | – | – | {res['error']} | |")
                continue
            for k, r in enumerate(res["rows"]):
                lines.append(
                    f"| {s['solver']} | {s['method']} | {res['compile_s']:.1f} | {res['peak_rss_mb']:.0f} | "
                    f"{r['rtol']:.0e} | {r['run_s']:.3f} | {r['psi_error']:.1e} | "
                    f"{_fmt(r.get('grad_error'))} |" if k == 0 else
                    f"| | | | | {r['rtol']:.0e} | {r['run_s']:.3f} | {r['psi_error']:.1e} | "
                    f"{_fmt(r.get('grad_error'))} |")
        lines.append("")
    if "modes" in data:
        lines += [f"### Cost versus retained modes (`{nx} x {ny}` mesh, t1 = {t1}, Tsit5, rtol 1e-10)", "",
                  "![modes](results/modes.png)", "",
                  "| modes | method | compile [s] | run [s] | peak RSS [MB] |", "|---:|---|---:|---:|---:|"]
        for r in data["modes"]:
            s = r["spec"]
            lines.append(f"| {s['case'][2]} | {s['method']} | " + (f"{r['error']} | | |" if "error" in r else
                         f"{r['compile_s']:.1f} | {r['rows'][0]['run_s']:.3f} | {r['peak_rss_mb']:.0f} |"))
        lines.append("")
    if "scaling" in data:
        lines += [f"### Cost versus design variables ({n_modes} modes, t1 = {t1}, Tsit5, rtol 1e-10, one run each)", "",
                  "Single runs on a shared machine: a row can be off by 2x (a forward run slower than the "
                  "gradients of the same mesh is such noise), and compile = first call - run is unreliable "
                  "where the run dominates (fd). The sparse FE path (bench_scale.py) extends the adjoint to 1e5 variables.", "",
                  "![scaling](results/scaling.png)", "",
                  "| mesh | design variables | method | compile [s] | run [s] | run / forward | peak RSS [MB] |",
                  "|---|---:|---|---:|---:|---:|---:|"]
        forward = {tuple(r["spec"]["case"][:2]): r["rows"][0]["run_s"] for r in data["scaling"]
                   if "error" not in r and r["spec"]["method"] == "forward"}
        for r in data["scaling"]:
            s = r["spec"]
            mesh = f"{s['case'][0]} x {s['case'][1]}"
            if "error" in r:
                lines.append(f"| {mesh} | | {s['method']} | {r['error']} | | | |")
                continue
            ratio = r["rows"][0]["run_s"] / forward.get(tuple(s["case"][:2]), float("nan"))
            lines.append(f"| {mesh} | {r['n_design']} | {s['method']} | {r['compile_s']:.1f} | "
                         f"{r['rows'][0]['run_s']:.3f} | {ratio:.1f} | {r['peak_rss_mb']:.0f} |")
        lines.append("")
    return "\n".join(lines)


def write_section(text: str):
    """Rewrite this script's section of RESULTS.md (`_results.write_section`), leaving the others as they are."""
    from _results import write_section as write

    write(SECTION.removeprefix("## "), text.removeprefix(SECTION))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--study", nargs="+", default=["wp", "modes", "scaling"], choices=["wp", "modes", "scaling"])
    parser.add_argument("--case", nargs=5, type=float, default=[12, 2, 4, 0.15, 0.05],
                        metavar=("NX", "NY", "MODES", "T1", "T_RAMP"))
    parser.add_argument("--solvers", nargs="+", default=["Tsit5", "Dopri8"])
    parser.add_argument("--rtols", nargs="+", type=float, default=[1e-6, 1e-8, 1e-10])
    parser.add_argument("--modes", nargs="+", type=int, default=[6, 12, 20, 30])
    parser.add_argument("--meshes", nargs="+", default=["12x2", "27x4", "52x6", "102x6"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--timeout", type=float, default=1800)
    parser.add_argument("--render", metavar="JSON", help="only redraw figures and tables from a saved JSON")
    args = parser.parse_args()
    if args.render:
        saved = json.loads(pathlib.Path(args.render).read_text())
        plots(saved["data"])
        text = markdown(saved["data"], saved["command"], saved["case"])
        (RESULTS / "work_precision.md").write_text(text + "\n")
        write_section(text)
        print(text)
        return
    if args.worker:
        spec = json.loads(args.worker)
        spec["case"] = [int(spec["case"][0]), int(spec["case"][1]), int(spec["case"][2]), *spec["case"][3:]]
        print(json.dumps(worker(spec)))
        return
    args.case = [int(args.case[0]), int(args.case[1]), int(args.case[2]), args.case[3], args.case[4]]
    args.meshes = [tuple(int(v) for v in m.split("x")) for m in args.meshes]
    RESULTS.mkdir(exist_ok=True)
    command = "flock /tmp/ffr_bench.lock python benchmarks/bench_work_precision.py " + " ".join(sys.argv[1:])

    def log(msg):
        print(msg, flush=True)

    data = {}
    if "wp" in args.study:
        data["work_precision"] = study_work_precision(args, log)
    if "modes" in args.study:
        data["modes"] = study_modes(args, log)
    if "scaling" in args.study:
        data["scaling"] = study_scaling(args, log)
    (RESULTS / "work_precision.json").write_text(json.dumps({"command": command.strip(), "case": args.case,
                                                              "data": data}, indent=1))
    plots(data)
    text = markdown(data, command.strip(), args.case)
    (RESULTS / "work_precision.md").write_text(text + "\n")
    write_section(text)
    print(text)


if __name__ == "__main__":
    main()
