"""The design gradient of the reference slider–crank (issue 4; paper Sect. 4.3, Figs. 5–6).

At `x = 0.5` everywhere (588 densities for the reference mesh), forward tolerances rtol 1e-10 /
atol 1e-12 (the paper's), and by default the paper's backward tolerances 1e-8 / 1e-10:

1. `psi` and the adjoint gradient (the paper's adjoint variable method);
2. accuracy: adjoint vs autodiff (relative max-norm difference), central finite differences on
   entries spread over the rod vs the adjoint, with a step study on a few entries that picks the step;
3. the sign pattern per element row (the paper: outer rows negative, inner rows positive) and a PNG of
   the field like the paper's Figs. 5–6;
4. timings in one run, compile separate (`jit(...).lower(x).compile()`), medians of run times:
   forward, adjoint, autodiff, backsolve, direct, finite differences, and ratios gradient / forward.
   The direct method (one forward-mode tangent per scene parameter) is extrapolated from timed
   batches of a few tangents (`t(k) = a + b k`, fitted on two batch sizes), finite differences from
   the forward run time (`2 n + 1` solves).

Usage (from the repository root; on a shared machine wrap timing runs in `flock /tmp/ffr_bench.lock`):
`python benchmarks/bench_gradient.py [--nx 100 --ny 6 --modes 6 --t1 3 --runs 3 --fd-entries 20]`.
The reference case writes `benchmarks/results/gradient.md`, `gradient.json`, `gradient_field.png`
and its section of `benchmarks/RESULTS.md`; other sizes write under `--out` only.
"""

import argparse
import json
import os
import pathlib
import platform
import statistics
import sys
import time

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj
from ffr_jax._app._gradient_plot import row_signs

SECTION = "## Gradient of the reference case"
REFERENCE = {"nx": 100, "ny": 6, "modes": 6, "t1": 3.0}
HERE = pathlib.Path(__file__).parent


def compile_and_time(fn, args, runs):
    """Compile `jax.jit(fn)` at `args`, run it `runs` times. Returns (result, compile_s, samples)."""
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - start
    samples, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = jax.block_until_ready(compiled(*args))
        samples.append(time.perf_counter() - start)
    return result, compile_s, samples


def relative_max(a, b):
    """`max|a - b| / max|b|`."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def spread_entries(case, count):
    """`count` design indices spread along the rod (evenly spaced columns) and over all element rows."""
    ny, n = case.mesh.ny, case.mesh.nx - 2
    columns = np.linspace(0, n - 1, count).round().astype(int)
    return sorted({(k % ny) * n + int(c) for k, c in enumerate(columns)})


def _modal_solver(case):
    """The modal solver the case's rod takes (AutoModes resolved)."""
    solver = case.design.reduction.solver
    return solver.choose(case.design.model) if isinstance(solver, fj.AutoModes) else solver


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=REFERENCE["nx"])
    parser.add_argument("--ny", type=int, default=REFERENCE["ny"])
    parser.add_argument("--modes", type=int, default=REFERENCE["modes"])
    parser.add_argument("--t1", type=float, default=REFERENCE["t1"])
    parser.add_argument("--value", type=float, default=0.5)
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--atol", type=float, default=1e-12)
    parser.add_argument("--backward-rtol", type=float, default=1e-8, help="adjoint / backsolve (paper: 1e-8)")
    parser.add_argument("--backward-atol", type=float, default=1e-10, help="adjoint / backsolve (paper: 1e-10)")
    parser.add_argument("--runs", type=int, default=3, help="timed runs of forward and adjoint (median)")
    parser.add_argument("--other-runs", type=int, default=2, help="timed runs of autodiff and backsolve")
    parser.add_argument("--fd-entries", type=int, default=20, help="entries checked by central differences")
    parser.add_argument("--study-entries", type=int, default=2, help="entries of the finite-difference step study")
    parser.add_argument("--study-steps", type=float, nargs="+", default=[1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6])
    parser.add_argument("--tangents", type=int, nargs=2, default=[1, 4],
                        help="two batch sizes of forward-mode tangents timed to extrapolate the direct method")
    parser.add_argument("--out", type=pathlib.Path, default=None,
                        help="directory of the detailed results (default benchmarks/results for the reference "
                             "case; required otherwise)")
    args = parser.parse_args(argv)
    is_reference = (args.nx, args.ny, args.modes, args.t1) == tuple(REFERENCE.values())
    if args.out is None and not is_reference:
        parser.error("--out DIR is required for a case other than the reference one (RESULTS.md holds the reference)")
    out = args.out if args.out is not None else HERE / "results"
    out.mkdir(parents=True, exist_ok=True)
    command = "python benchmarks/bench_gradient.py" + ("" if argv is None and len(sys.argv) == 1 else
                                                        " " + " ".join(sys.argv[1:] if argv is None else argv))

    case = fj.cases.slider_crank(args.nx, args.ny, args.modes, args.t1)
    x = case.initial_design(args.value)
    tol = dict(rtol=args.rtol, atol=args.atol)
    backward = dict(rtol=args.backward_rtol, atol=args.backward_atol)
    log = print

    # --- forward -------------------------------------------------------------------------------
    def forward(x):
        traj = fj.simulate(case, x, **tol)
        return traj.psi, traj.num_steps

    (psi, steps), fwd_compile, fwd_samples = compile_and_time(forward, (x,), args.runs)
    psi, steps = float(psi), int(steps)
    fwd = statistics.median(fwd_samples)
    log(f"forward: psi = {psi:.10e}, {steps} steps, compile {fwd_compile:.1f} s, run {fwd:.3f} s")

    # --- gradients -----------------------------------------------------------------------------
    timings = {"forward": (fwd_compile, fwd_samples)}
    grads = {}
    methods = {
        "adjoint": (fj.Adjoint(**backward), args.runs),
        "autodiff": ("autodiff", args.other_runs),
        "backsolve": (fj.Backsolve(**backward), args.other_runs),
    }
    for name, (method, runs) in methods.items():
        (p, g), c, samples = compile_and_time(lambda x, m=method: fj.value_and_grad(case, x, m, **tol), (x,), runs)
        grads[name] = np.asarray(g)
        timings[name] = (c, samples)
        log(f"{name}: psi {float(p):.10e}, compile {c:.1f} s, run {statistics.median(samples):.3f} s, "
            f"max|grad| {np.abs(grads[name]).max():.4e}")
    adjoint = grads["adjoint"]

    # Direct: forward-mode tangents of psi with respect to the scene parameters p, timed for two
    # batch sizes and extrapolated to all parameters (the direct method needs one tangent each).
    scene = case.scene(x)
    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(dyn)

    def psi_of_parameters(v):
        s = eqx.combine(unravel(v), static)
        return fj.simulate(case.model, s, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
                           adjoint=diffrax.ForwardMode(), jump_ts=case.jump_ts, **tol).psi

    tangent_times = {}
    rng = np.random.default_rng(0)
    for k in args.tangents:
        basis = jnp.asarray(rng.normal(size=(k, flat.size)))
        _, c, samples = compile_and_time(
            lambda v, b: jax.vmap(lambda e: jax.jvp(psi_of_parameters, (v,), (e,))[1])(b), (flat, basis), 1)
        tangent_times[k] = (c, samples[0])
        log(f"direct, {k} tangents: compile {c:.1f} s, run {samples[0]:.3f} s")
    (k1, (c1, t1_)), (k2, (_, t2_)) = sorted(tangent_times.items())
    slope = (t2_ - t1_) / (k2 - k1)
    direct_estimate = t1_ + slope * (flat.size - k1)
    log(f"direct (all {flat.size} scene parameters, extrapolated): {direct_estimate:.1f} s")

    # --- finite differences: step study, then entries spread over the rod ---------------------
    psi_only = jax.jit(lambda x: fj.objective(case, x, **tol)).lower(x).compile()

    def central(k, h):
        e = jnp.zeros_like(x).at[k].set(h)
        return float((psi_only(x + e) - psi_only(x - e)) / (2 * h))

    entries = spread_entries(case, args.fd_entries)
    study_entries = [int(np.argmax(np.abs(adjoint)))] + entries[len(entries) // 2: len(entries) // 2 + args.study_entries - 1]
    study = {}
    for h in args.study_steps:
        if not (case.material.x_min <= args.value - h and args.value + h <= 1.0):
            continue
        study[h] = [abs(central(k, h) - adjoint[k]) / np.abs(adjoint).max() for k in study_entries]
        log(f"step {h:.0e}: relative errors {', '.join(f'{e:.2e}' for e in study[h])}")
    step = min(study, key=lambda h: max(study[h]))
    fd_start = time.perf_counter()
    fd = {k: central(k, step) for k in entries}
    fd_wall = time.perf_counter() - fd_start
    fd_err = max(abs(fd[k] - adjoint[k]) for k in entries) / np.abs(adjoint).max()
    fd_estimate = (2 * case.n_design + 1) * fwd
    log(f"central differences, step {step:.0e}, {len(entries)} entries: max error {fd_err:.2e} of max|grad| "
        f"({fd_wall:.1f} s; all {case.n_design} entries ~ {fd_estimate:.0f} s)")

    # --- sign pattern and picture --------------------------------------------------------------
    rows = row_signs(case, adjoint)
    figure = fj.plot_gradient(case, adjoint, title=f"adjoint gradient dpsi/dx_e, {args.nx} x {args.ny} rod, "
                                                   f"x = {args.value}, psi = {psi:.6e}")
    png = out / "gradient_field.png"
    figure.savefig(png, dpi=130)

    # --- report --------------------------------------------------------------------------------
    adj_vs_auto = relative_max(adjoint, grads["autodiff"])
    back_vs_auto = relative_max(grads["backsolve"], grads["autodiff"])
    adj_run = statistics.median(timings["adjoint"][1])
    ratio = adj_run / fwd
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    device = jax.devices()[0]
    header = [
        f"Case: slider-crank {args.nx} x {args.ny}, {args.modes} modes, t1 = {args.t1} s, x = {args.value} "
        f"({case.n_design} design variables, {flat.size} scene parameters, {type(_modal_solver(case)).__name__}); "
        f"forward Dopri8 (the default solver) rtol {args.rtol:g} / "
        f"atol {args.atol:g} ({steps} steps); adjoint and backsolve backward rtol {args.backward_rtol:g} / "
        f"atol {args.backward_atol:g}.",
        f"Machine: {device.platform}, {os.cpu_count()} CPUs shared with other sessions (load average at the end "
        f"{load}), jax {jax.__version__}, {platform.python_version()}. Medians of {args.runs} runs (forward, "
        f"adjoint) and {args.other_runs} (autodiff, backsolve) after compilation; compile timed separately.",
    ]
    accuracy = [
        f"- psi = {psi:.10e}; max |grad| = {np.abs(adjoint).max():.4e} (the paper, for its own model: 7.4e-3)",
        f"- adjoint vs autodiff: relative max-norm difference {adj_vs_auto:.2e} (target 1e-5: "
        f"{'met' if adj_vs_auto <= 1e-5 else 'NOT met'}); backsolve vs autodiff {back_vs_auto:.2e}",
        f"- central differences on {len(entries)} entries spread over all rows, step {step:g} (chosen by the step "
        f"study below): max |fd - adjoint| / max|grad| = {fd_err:.2e} (target 1e-4: "
        f"{'met' if fd_err <= 1e-4 else 'NOT met'})",
        "- sign pattern by element row (bottom to top): " + "; ".join(
            f"row {r['row']} [{r['y_min']:+.2f}, {r['y_max']:+.2f}] {r['sign']} ({r['n_negative']}-/{r['n_positive']}+)"
            for r in rows),
    ]
    table = [
        "| computation | compile [s] | run, median [s] | run / forward |",
        "|---|---:|---:|---:|",
        f"| forward (psi) | {fwd_compile:.1f} | {fwd:.3f} | 1.00 |",
    ]
    for name in ("adjoint", "autodiff", "backsolve"):
        c, samples = timings[name]
        med = statistics.median(samples)
        table.append(f"| {name} gradient | {c:.1f} | {med:.3f} | {med / fwd:.2f} |")
    table.append(f"| direct gradient ({flat.size} tangents; extrapolated from {k1} and {k2}: "
                 f"{t1_:.2f} s and {t2_:.2f} s) | {c1:.1f} | ~{direct_estimate:.1f} | ~{direct_estimate / fwd:.1f} |")
    table.append(f"| finite differences ({2 * case.n_design + 1} forward solves, extrapolated) | {fwd_compile:.1f} "
                 f"| ~{fd_estimate:.0f} | ~{fd_estimate / fwd:.0f} |")
    targets = (f"Targets: adjoint gradient <= 3 s run time: {adj_run:.2f} s ({'met' if adj_run <= 3 else 'NOT met'}); "
               f"<= 3x one forward simulation: {ratio:.2f}x ({'met' if ratio <= 3 else 'NOT met'}).")
    study_table = ["| step h | " + " | ".join(f"entry {k}" for k in study_entries) + " |",
                   "|---:|" + "---:|" * len(study_entries)]
    study_table += [f"| {h:g} | " + " | ".join(f"{e:.2e}" for e in errs) + " |" for h, errs in study.items()]
    fd_table = ["| entry | row | column | adjoint | central differences | difference / max|grad| |",
                "|---:|---:|---:|---:|---:|---:|"]
    n_col = case.mesh.nx - 2
    fd_table += [f"| {k} | {k // n_col} | {k % n_col + 1} | {adjoint[k]:.6e} | {fd[k]:.6e} | "
                 f"{abs(fd[k] - adjoint[k]) / np.abs(adjoint).max():.2e} |" for k in entries]

    details = "\n".join([
        f"# bench_gradient: {args.nx} x {args.ny}, {args.modes} modes, t1 = {args.t1}", "",
        f"Command: `{command}`", "", *header, "", "## Accuracy", "", *accuracy, "", "## Timings", "", *table, "",
        targets, "", "## Finite-difference step study", "",
        "Error of central differences relative to max|grad| for each step, on the entry with the largest "
        "gradient and further entries; truncation error falls as h^2 while the solver's tolerance-level noise "
        "in psi grows as 1/h, so the smallest error marks the step used.", "", *study_table, "",
        "## Central differences vs adjoint", "", *fd_table, "",
        f"Picture: `{png.name}`.", "",
    ])
    (out / "gradient.md").write_text(details)
    (out / "gradient.json").write_text(json.dumps({
        "psi": psi, "grad_adjoint": adjoint.tolist(), "grad_autodiff": grads["autodiff"].tolist(),
        "grad_backsolve": grads["backsolve"].tolist(), "fd": {str(k): v for k, v in fd.items()}, "fd_step": step,
        "step_study": {str(h): e for h, e in study.items()}, "rows": rows,
        "timings": {name: {"compile_s": c, "runs_s": s} for name, (c, s) in timings.items()}
        | {"direct_estimate_s": direct_estimate, "direct_tangents": {str(k): v for k, v in tangent_times.items()},
           "fd_estimate_s": fd_estimate},
    }, indent=1))
    print(details)

    if is_reference and args.out is None:
        section = "\n".join([
            SECTION, "", f"Command: `flock /tmp/ffr_bench.lock {command}` (details: `benchmarks/results/gradient.md`, "
            "picture: `benchmarks/results/gradient_field.png`).", "", *header, "", *accuracy, "", *table, "",
            targets, "",
        ])
        write_section(HERE / "RESULTS.md", section)


def write_section(path: pathlib.Path, section: str) -> None:
    """Rewrite this benchmark's section of RESULTS.md (`_results.write_section`), leaving the others alone."""
    import _results

    if path != _results.RESULTS:
        raise ValueError(f"write_section writes {_results.RESULTS}, not {path}")
    _results.write_section(SECTION.removeprefix("## "), section.removeprefix(SECTION))


if __name__ == "__main__":
    main()
