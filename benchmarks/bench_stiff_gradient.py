"""Gradient of the reference slider–crank with the stiff route versus Dopri8, at several mode counts (issue 15).

The paper's adjoint (`ffr_jax.Adjoint`) with the Rosenbrock method Rodas5P forward and, on the
forward's accepted steps, backward (`ffr_jax/_sensitivity/_forward_grid.py`; `adjoint-adaptive:rodas5p`
for diffrax's adaptive backward solve), against the adjoint with Dopri8 and autodiff / backsolve
with either solver. For each configuration: compile time, median run time, psi and gradient errors
against a tight reference (`--reference`, default autodiff through Rodas5P at rtol 1e-11, see
`reference`), forward steps and time with the same solver, and the process's peak RSS (the
reference is computed in a process of its own). Each configuration runs in its own process;
rows are written as they finish.

Methods (`--methods`): `adjoint:dopri8`, `adjoint:rodas5p`, `autodiff:dopri8`, `autodiff:rodas5p`,
`backsolve:rodas5p`, `discrete:rodas5p` (`ffr_jax.DiscreteAdjoint`, the discrete adjoint of Rodas5P); `--rtols` the forward tolerance (atol = 1e-2 rtol), the adjoint's backward
tolerance `--backward-rtol` (default: the forward one; atol = 1e-2 of it).

Usage:
```
flock /tmp/ffr_bench.lock python benchmarks/bench_stiff_gradient.py --modes 6 15 30
python benchmarks/bench_stiff_gradient.py --modes 6 --methods adjoint:rodas5p --rtols 1e-6 --runs 1 --no-write
```
Writes `benchmarks/results/<out>.json` and `.md` (with the 30 / 6 modes ratios); references in
`results/stiff_gradient_ref_<modes>_<reference>.npz`.
"""

import argparse
import json
import os
import pathlib
import resource
import statistics
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).parent
RESULTS = HERE / "results"


def _method(name, rtol, backward_rtol, chunk, backward_atol=None):
    import diffrax

    import ffr_jax
    from ffr_jax._solver import Rodas5P

    kind, solver_name = name.split(":")
    grid = None
    if kind == "adjoint-adaptive":
        kind, grid = "adjoint", "adaptive"
    solver = {"dopri8": diffrax.Dopri8(), "rodas5p": Rodas5P()}[solver_name]
    if kind == "adjoint":
        b = rtol if backward_rtol is None else backward_rtol
        a = b * 1e-2 if backward_atol is None else backward_atol
        return ffr_jax.Adjoint(rtol=b, atol=a, solver=solver, chunk=chunk, grid=grid), solver
    if kind == "autodiff":
        return ffr_jax.Autodiff(), solver
    if kind == "discrete":
        return ffr_jax.DiscreteAdjoint(), solver
    if kind == "backsolve":
        b = rtol if backward_rtol is None else backward_rtol
        a = b * 1e-2 if backward_atol is None else backward_atol
        return ffr_jax.Backsolve(rtol=b, atol=a), solver
    raise ValueError(name)


def reference(case, x, path, spec):
    """`(psi, grad)` of the accuracy reference `spec` ("method:solver:rtol", cached in `path`).

    Default `autodiff:rodas5p:1e-11`: the discrete derivative through the stiff solver at a tight
    tolerance, a different route from the paper's adjoint (no backward ODE, no quadrature) and free
    of the explicit solver's stability limit (autodiff through Dopri8 is not: its derivative was
    3.2e-3 off at 20 modes even at rtol 1e-12, RESULTS.md). `adjoint:dopri8:1e-12` (adaptive
    backward, atol 1e-16) is the explicit-route alternative, used to check the default at 6 modes.
    """
    import numpy as np

    import ffr_jax

    if path.exists():
        data = np.load(path)
        return float(data["psi"]), data["grad"]
    name, rtol = spec.rsplit(":", 1)
    rtol = float(rtol)
    method, solver = _method(name, rtol, rtol, None, 1e-16)
    psi, grad = ffr_jax.value_and_grad(case, x, method, rtol=rtol, atol=rtol * 1e-2, solver=solver,
                                       max_steps=1_000_000)
    np.savez(path, psi=float(psi), grad=np.asarray(grad))
    return float(psi), np.asarray(grad)


def worker(spec):
    import equinox as eqx
    import jax
    import numpy as np

    import ffr_jax

    mesh = spec.get("mesh")  # None: the reference case (100 x 6, t1 = 3 s)
    if mesh is None:
        case = ffr_jax.cases.slider_crank(n_modes=spec["modes"])
        tag = f"{spec['modes']}"
    else:
        case = ffr_jax.cases.slider_crank(mesh[0], mesh[1], spec["modes"], mesh[2])
        tag = f"{spec['modes']}_{mesh[0]}x{mesh[1]}_t{mesh[2]:g}"
    x = case.initial_design(0.5)
    ref_tag = spec["reference"].replace(":", "_")
    start = time.perf_counter()
    psi_ref, grad_ref = reference(case, x, RESULTS / f"stiff_gradient_ref_{tag}_{ref_tag}.npz", spec["reference"])
    if spec.get("only_reference"):  # its own process, so that no row's peak memory includes it
        return {**spec, "reference_s": time.perf_counter() - start, "psi": psi_ref}
    method, solver = _method(spec["method"], spec["rtol"], spec["backward_rtol"], spec["chunk"],
                             spec.get("backward_atol"))
    rtol = spec["rtol"]

    @eqx.filter_jit
    def gradient(x):
        return ffr_jax.value_and_grad(case, x, method, rtol=rtol, atol=rtol * 1e-2, solver=solver,
                                      max_steps=spec["max_steps"])

    out = dict(spec)
    start = time.perf_counter()
    compiled = gradient.lower(x).compile()
    out["compile_s"] = time.perf_counter() - start
    samples = []
    for _ in range(spec["runs"]):
        start = time.perf_counter()
        psi, grad = jax.block_until_ready(compiled(x))
        samples.append(time.perf_counter() - start)
        if samples[-1] > spec["slow_s"]:
            break
    grad = np.asarray(grad)
    if spec.get("save_dir"):
        save = pathlib.Path(spec["save_dir"])
        save.mkdir(parents=True, exist_ok=True)
        np.savez(save / f"{tag}_{spec['method'].replace(':', '_')}_{spec['rtol']:g}.npz", psi=float(psi), grad=grad,
                 psi_ref=psi_ref, grad_ref=grad_ref)
    out.update(run_s=statistics.median(samples), runs=len(samples), psi=float(psi),
               psi_rel_error=abs(float(psi) - psi_ref) / abs(psi_ref),
               grad_rel_error=float(np.max(np.abs(grad - grad_ref)) / np.max(np.abs(grad_ref))),
               max_abs_grad=float(np.max(np.abs(grad_ref))))
    # One forward solve with the same solver and tolerances, for the ratio gradient / forward.
    forward = eqx.filter_jit(lambda x: ffr_jax.simulate(case, x, rtol=rtol, atol=rtol * 1e-2, solver=solver,
                                                              max_steps=spec["max_steps"]))
    traj = jax.block_until_ready(forward(x))
    fwd = []
    for _ in range(max(spec["runs"], 3)):
        start = time.perf_counter()
        jax.block_until_ready(forward(x))
        fwd.append(time.perf_counter() - start)
    out.update(forward_s=statistics.median(fwd), forward_steps=int(traj.num_accepted_steps))
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["load"] = os.getloadavg()
    return out


def markdown(data):
    loads = [r["load"][0] for r in data["rows"] if "load" in r]
    load = f" Load average (1 min) at the end of the rows: {min(loads):.1f}..{max(loads):.1f} on 2 cores." if loads else ""
    machine = f"Machine: {data['machine']}; {data['threads']}." if "machine" in data else "Machine: (not recorded with --no-write)."
    lines = [f"Command: `{data['command']}`", "", f"{machine}{load}", "",
             "| modes | method:solver | rtol fwd / bwd | compile [s] | run [s] | forward [s] (steps) | run / forward | "
             "psi rel. error | grad rel. error (max norm) | peak RSS [MB] |",
             "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in data["rows"]:
        if "error" in r:
            lines.append(f"| {r['modes']} | {r['method']} | {r['rtol']:g} | {r['error']} | | | | | | |")
            continue
        b = r["backward_rtol"] if r["backward_rtol"] is not None else r["rtol"]
        bwd = f" / {b:g}" if not r["method"].startswith("autodiff") else ""
        lines.append(f"| {r['modes']} | {r['method']} | {r['rtol']:g}{bwd} | {r['compile_s']:.1f} | {r['run_s']:.3f} | "
                     f"{r['forward_s']:.3f} ({r['forward_steps']}) | {r['run_s'] / r['forward_s']:.2f} | "
                     f"{r['psi_rel_error']:.1e} | {r['grad_rel_error']:.1e} | {r['peak_rss_mb']:.0f} |")
    done = {(r["modes"], r["method"], r["rtol"]): r for r in data["rows"] if "error" not in r}
    ratios = []
    for (modes, method, rtol), r in done.items():
        low = done.get((6, method, rtol))
        if modes == 30 and low is not None:
            ratios.append(f"| {method} | {rtol:g} | {r['forward_s'] / low['forward_s']:.2f} | "
                          f"{r['run_s'] / low['run_s']:.2f} |")
    if ratios:
        lines += ["", "| method:solver | rtol | forward 30 / 6 modes | gradient 30 / 6 modes |", "|---|---:|---:|---:|",
                  *ratios]
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[6, 15, 30])
    parser.add_argument("--methods", nargs="+", default=["adjoint:dopri8", "adjoint:rodas5p", "autodiff:dopri8",
                                                         "autodiff:rodas5p"])
    parser.add_argument("--rtols", type=float, nargs="+", default=[1e-6, 1e-8])
    parser.add_argument("--backward-rtol", type=float, default=None)
    parser.add_argument("--backward-atol", type=float, default=None,
                        help="atol of the adjoint/backsolve backward solve (default 1e-2 of its rtol; the adjoint "
                             "states are of the size of psi, so small cases need ~1e-16)")
    parser.add_argument("--chunk", type=int, default=None, help="Adjoint(chunk=...); default: sized by the parameters")
    parser.add_argument("--mesh", type=float, nargs=3, default=None, metavar=("NX", "NY", "T1"),
                        help="a smaller slider-crank (default: the reference case 100 x 6, t1 = 3 s)")
    parser.add_argument("--out", default="stiff_gradient", help="name of the results files")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--slow-s", type=float, default=60.0)
    parser.add_argument("--max-steps", type=int, default=200_000)
    parser.add_argument("--timeout", type=float, default=3600.0)
    parser.add_argument("--reference", default="autodiff:rodas5p:1e-11",
                        help="accuracy reference, method:solver:rtol (see `reference`)")
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(json.loads(args.worker))))
        return
    RESULTS.mkdir(exist_ok=True)
    data = {"command": "python benchmarks/bench_stiff_gradient.py " + " ".join(sys.argv[1:]), "rows": [],
            "threads": "XLA_FLAGS=" + os.environ.get("XLA_FLAGS", "(default)")}
    for n_modes in args.modes:
        spec = {"modes": n_modes, "reference": args.reference, "only_reference": True,
                "mesh": None if args.mesh is None else [int(args.mesh[0]), int(args.mesh[1]), args.mesh[2]]}
        proc = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(HERE.parent)})
        print(proc.stdout.strip().splitlines()[-1] if proc.returncode == 0 else proc.stderr[-2000:], flush=True)
        for method in args.methods:
            for rtol in args.rtols:
                spec = {"modes": n_modes, "method": method, "rtol": rtol, "backward_rtol": args.backward_rtol,
                        "chunk": args.chunk, "backward_atol": args.backward_atol, "runs": args.runs, "slow_s": args.slow_s, "max_steps": args.max_steps,
                        "save_dir": str(RESULTS / f"{args.out}_gradients"), "reference": args.reference,
                        "mesh": None if args.mesh is None else [int(args.mesh[0]), int(args.mesh[1]), args.mesh[2]]}
                try:
                    proc = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)], capture_output=True,
                                          text=True, timeout=args.timeout, env={**os.environ, "PYTHONPATH": str(HERE.parent)})
                    if proc.returncode != 0:
                        row = {**spec, "error": proc.stderr.strip().splitlines()[-1][:160]}
                    else:
                        row = json.loads(proc.stdout.strip().splitlines()[-1])
                except subprocess.TimeoutExpired:
                    row = {**spec, "error": f"timed out after {args.timeout:.0f} s"}
                print(json.dumps(row), flush=True)
                data["rows"].append(row)
                if not args.no_write:  # after every row: a killed run keeps what it measured
                    write(args.out, data)
    text = write(args.out, data) if not args.no_write else markdown(data)
    print(text)


def write(out, data):
    import _results

    data["machine"] = _results.machine()
    text = markdown(data)
    (RESULTS / f"{out}.json").write_text(json.dumps(data, indent=1))
    (RESULTS / f"{out}.md").write_text(text)
    return text


if __name__ == "__main__":
    main()
