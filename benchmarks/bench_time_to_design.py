"""Time to a design: the reference rod optimised with the defaults that end crisp (issue 30).

`fj.optimize` with `fj.MMA`'s defaults (move 0.2), a cone filter, the Heaviside projection and the default
continuation `fj.beta_continuation()` (beta 1 -> 32, doubled every 10 steps; no `beta` given), volume <= 0.5,
on the reference rod (REFERENCE_CASE: t1 = 3 s, 6 modes, the default gradient route) on a mesh of `--nx` x
`--ny` elements. Reports the mesh size, iterations, wall time and what it was spent on (the objective's
gradient calls, of which the FE stage (modes and body data) is measured alone once and multiplied by the number
of calls; the rest: MMA, constraints, projection, driver), psi of the final physical design against the uniform
design of equal volume (both at the paper's forward tolerances rtol 1e-10, atol 1e-12), the volume, the grey
share (`fj.grey_share`, 0.1 < x_phys < 0.9) and a density picture.

Usage: `python benchmarks/bench_time_to_design.py [--nx 50 --ny 6 --iters 60 --filter-length M]`. Writes
`benchmarks/results/time_to_design/` (summary.json, design.png, convergence.png) and the section "Time to a
design" of RESULTS.md.
"""

import argparse
import json
import pathlib
import time

import jax
import numpy as np

import ffr_jax as fj


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=50)
    parser.add_argument("--ny", type=int, default=6)
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--t1", type=float, default=3.0)
    parser.add_argument("--iters", type=int, default=60)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--filter-radius", type=float, default=1.5, help="in element sizes")
    parser.add_argument("--beta-every", type=int, default=None,
                        help="steps between doublings of beta (default: none given, fj.optimize's continuation)")
    parser.add_argument("--rtol", type=float, default=1e-8, help="tolerance of the solves inside the loop")
    parser.add_argument("--out", type=pathlib.Path,
                        default=pathlib.Path(__file__).parent / "results" / "time_to_design")
    parser.add_argument("--no-results", action="store_true", help="do not write RESULTS.md")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    start_all = time.perf_counter()
    case = fj.cases.slider_crank(args.nx, args.ny, args.modes, args.t1)
    x_min = case.material.x_min
    filt = fj.DensityFilter(case.design, args.filter_radius)
    projection = fj.HeavisideProjection(0.5, x_min=x_min)
    fun = fj.make_objective(case, filter=filt, projection=projection, rtol=args.rtol)
    volume = fj.VolumeConstraint(args.volume, x_min=x_min, filter=filt, projection=projection)
    setup_s = time.perf_counter() - start_all

    calls = []

    def timed_fun(x, beta):
        start = time.perf_counter()
        value, grad = jax.block_until_ready(fun(x, beta))
        calls.append(time.perf_counter() - start)
        return value, grad

    for name in ("projection", "compiles_itself", "design_size", "fingerprint"):
        setattr(timed_fun, name, getattr(fun, name))

    x0 = case.initial_design(args.volume)
    start = time.perf_counter()
    schedule = fj.beta_continuation() if args.beta_every is None else fj.beta_continuation(every=args.beta_every)
    result = fj.optimize(timed_fun, x0, fj.MMA(x_min), volume, iterations=args.iters, progress=True,
                         beta=None if args.beta_every is None else schedule)
    run_s = time.perf_counter() - start
    h = result.history
    beta_last = schedule(h.steps - 1)
    x_phys = np.asarray(fj.physical_densities(result.x, filt, projection, beta_last))

    # The FE stage alone (modes and body data of the design), compiled, then timed once per gradient call.
    fe = jax.jit(lambda x: case.modes(x))
    jax.block_until_ready(fe(x_phys))
    start = time.perf_counter()
    for _ in range(3):
        jax.block_until_ready(fe(x_phys))
    fe_s = (time.perf_counter() - start) / 3

    start = time.perf_counter()
    uniform = case.initial_design(float(x_phys.mean()))
    psi_opt = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    psi_uniform = float(fj.objective(case, uniform, rtol=1e-10, atol=1e-12))
    evaluation_s = time.perf_counter() - start

    summary = {
        "mesh": f"{args.nx} x {args.ny}", "n_design": int(case.n_design), "modes": args.modes, "t1": args.t1,
        "filter_radius_elements": args.filter_radius, "iterations": int(h.steps), "beta_last": beta_last,
        "beta_every": args.beta_every or 10,
        "wall_time_s": run_s, "setup_s": setup_s, "first_gradient_s": calls[0],
        "later_gradients_s": float(np.sum(calls[1:])), "median_later_gradient_s": float(np.median(calls[1:])),
        "fe_stage_per_call_s": fe_s, "optimizer_and_driver_s": run_s - float(np.sum(calls)),
        "psi_optimised": psi_opt, "psi_uniform": psi_uniform, "ratio": psi_opt / psi_uniform,
        "volume": float(x_phys.mean()), "grey_share": float(fj.grey_share(x_phys)), "back_offs": result.back_offs,
        "feasible": bool(result.feasible), "grey_history": [float(g) for g in h.grey],
        "psi_history": [float(v) for v in h.value], "final_evaluation_s": evaluation_s,
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    np.savez(args.out / "design.npz", x=np.asarray(result.x), x_phys=x_phys, psi=h.value, grey=h.grey)
    ax = fj.plot_design(case, x_phys, title=f"reference rod {args.nx} x {args.ny}, MMA + continuation, "
                                             f"{h.steps} steps, V = {x_phys.mean():.3f}, "
                                             f"grey {100 * summary['grey_share']:.1f} %")
    ax.figure.savefig(args.out / "design.png", dpi=150)
    ax = fj.plot_history(h)
    ax.figure.savefig(args.out / "convergence.png", dpi=150)
    print(json.dumps({k: v for k, v in summary.items() if not k.endswith("history")}, indent=2))
    if not args.no_results:
        from _results import machine, write_section

        write_section("Time to a design", _section(args, summary, machine()))


def _section(args, s, where) -> str:
    n_calls = s["iterations"]
    fe_total = s["fe_stage_per_call_s"] * n_calls
    gradients = s["first_gradient_s"] + s["later_gradients_s"]
    return "\n".join([
        f"`python benchmarks/bench_time_to_design.py --nx {args.nx} --ny {args.ny} --iters {args.iters}"
        + ("" if args.beta_every is None else f" --beta-every {args.beta_every}") + "` "
        f"({where}). The reference rod (t1 = {args.t1} s, {args.modes} modes, default gradient route, rtol "
        f"{args.rtol:g} in the loop) on a {s['mesh']} mesh ({s['n_design']} densities), `fj.optimize` with "
        f"`fj.MMA`'s defaults, a {args.filter_radius}-element cone filter, the Heaviside projection and the "
        + ("the default continuation (no `beta` given: 1 -> 32, doubled every 10 steps)" if args.beta_every is None
           else f"the continuation `fj.beta_continuation(every={args.beta_every})` (1 -> 32, doubled every "
                f"{args.beta_every} steps: fj.optimize's default schedule twice as fast, to fit the time)")
        + f", volume <= {args.volume}.",
        "",
        "| quantity | value |",
        "|---|---:|",
        f"| mesh, densities | {s['mesh']}, {s['n_design']} |",
        f"| iterations (beta at the end) | {s['iterations']} ({s['beta_last']:g}) |",
        f"| wall time of the run | {s['wall_time_s']:.0f} s |",
        f"| gradient calls (first, with compile) | {s['first_gradient_s']:.1f} s |",
        f"| later gradient calls (sum; median each) | {s['later_gradients_s']:.0f} s; {s['median_later_gradient_s']:.2f} s |",
        f"| of which the FE stage (modes, measured alone x calls) | {fe_total:.0f} s ({s['fe_stage_per_call_s']:.3f} s each) |",
        f"| MMA, constraints, projection, driver | {s['optimizer_and_driver_s']:.1f} s |",
        f"| psi / psi(uniform, same volume) | {s['ratio']:.3f} |",
        f"| volume fraction | {s['volume']:.4f} |",
        f"| grey share (0.1 < x_phys < 0.9) | {100 * s['grey_share']:.1f} % |",
        f"| steps redone (back-offs) | {s['back_offs']} |",
        "",
        f"Gradients took {100 * gradients / s['wall_time_s']:.0f} % of the wall time. Picture: "
        "`benchmarks/results/time_to_design/design.png` (convergence: `convergence.png`); grey share per step in "
        "`summary.json`. Not shown here: the fine mesh (400 x 24) and the refinement check the issue asks for, "
        "the link example and the two links.",
    ]) + "\n"


if __name__ == "__main__":
    main()
