"""Time to a design: the reference rod optimised to a crisp 0/1 design, and the refinement check (issue 30).

`fj.optimize` with `fj.MMA`'s defaults (move 0.2), a cone filter (`--filter-length` in metres, or
`--filter-radius` in element sizes), the Heaviside projection (eta 0.5) and the continuation
`fj.beta_continuation(--beta-start, --beta-max, every=--beta-every)`, volume <= 0.5, on the reference rod
(REFERENCE_CASE: t1 = 3 s, 6 modes, the default gradient route) on a mesh of `--nx` x `--ny` elements. Reports the
mesh size, iterations, wall time and what it was spent on (the objective's gradient calls, of which the FE stage
(modes and body data) is measured alone once and multiplied by the number of calls; the rest: MMA, constraints,
projection, driver), psi of the final physical design against the uniform design of equal volume (both at the
paper's forward tolerances rtol 1e-10, atol 1e-12), the volume, the grey share (`fj.grey_share`,
0.1 < x_phys < 0.9) and a density picture. The run checkpoints into `<out>/run/` every 5 steps; `--resume`
continues a killed run there (bit for bit, see `fj.optimize`); `--force-resume` continues it with other settings
from the checkpoint on (e.g. `--beta-max 128 --iters 160`: the later steps at the higher beta).

With `--coarse DIR` (a run on half the elements per direction, same filter length and continuation) the summary
also holds the refinement check: the coarse physical design mapped onto this mesh (each coarse element = 2 x 2
fine ones), both thresholded at 0.5, and the share of the area where the two layouts differ.

Usage:
    python benchmarks/bench_time_to_design.py --nx 400 --ny 24 --filter-length 0.0075 --beta-max 64 \
        --iters 100 --out benchmarks/results/time_to_design_400x24
    python benchmarks/bench_time_to_design.py --nx 800 --ny 48 ... --coarse benchmarks/results/time_to_design_400x24
    python benchmarks/bench_time_to_design.py --write-results benchmarks/results/time_to_design_400x24 \
        benchmarks/results/time_to_design_800x48      # the RESULTS.md subsection from both summaries

Writes `<out>/` (summary.json, design.npz, design.png, convergence.png; `run/` holds the log and checkpoint).
"""

import argparse
import json
import pathlib
import time

import jax
import numpy as np

import ffr_jax as fj

SECTION = "The reference rod crisp on a fine mesh, and the refinement check (issue 30)"


def main():
    # As the ffr-jax command does, before JAX starts its backend: XLA's concurrency-optimised CPU scheduler off. A run
    # of bench_time_to_design_links.py without it hung once for 5 minutes at 0 % CPU in the Lanczos modal analysis's
    # host callback while building a case (benchmarks/RESULTS.md, "The two links", trap); with it, the same command ran.
    from ffr_jax._dynamics._xla_flags import avoid_batched_lapack_deadlock

    avoid_batched_lapack_deadlock()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=50)
    parser.add_argument("--ny", type=int, default=6)
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--t1", type=float, default=3.0)
    parser.add_argument("--iters", type=int, default=60)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--filter-radius", type=float, default=1.5, help="in element sizes")
    parser.add_argument("--filter-length", type=float, default=None,
                        help="filter radius in metres (overrides --filter-radius; the same physical filter on every mesh)")
    parser.add_argument("--beta-start", type=float, default=1.0)
    parser.add_argument("--beta-max", type=float, default=32.0)
    parser.add_argument("--beta-every", type=int, default=10, help="steps between doublings of beta")
    parser.add_argument("--rtol", type=float, default=1e-8, help="tolerance of the solves inside the loop")
    parser.add_argument("--eta-eroded", type=float, default=None,
                        help="with --eta-dilated: the robust formulation (objective on the eroded design)")
    parser.add_argument("--eta-dilated", type=float, default=None)
    parser.add_argument("--robust-objective", default="max", choices=("eroded", "blueprint", "dilated", "max"),
                        help="the design the objective is evaluated on (max: the largest over the three)")
    parser.add_argument("--resume", action="store_true", help="continue the run checkpointed in <out>/run")
    parser.add_argument("--force-resume", action="store_true",
                        help="continue it with other settings (e.g. a higher --beta-max from the checkpoint on)")
    parser.add_argument("--start-from", type=pathlib.Path, default=None,
                        help="a coarser run's folder: start from its design variables (nearest element centroid) "
                             "instead of the uniform design; with --beta-start at the coarse run's last beta, whether "
                             "its layout is still optimal on this mesh")
    parser.add_argument("--coarse", type=pathlib.Path, default=None,
                        help="a run's folder on half the elements per direction: the refinement check")
    parser.add_argument("--out", type=pathlib.Path,
                        default=pathlib.Path(__file__).parent / "results" / "time_to_design")
    parser.add_argument("--write-results", type=pathlib.Path, nargs=2, metavar=("COARSE", "FINE"), default=None,
                        help="only write the RESULTS.md subsection from two runs' summary.json")
    parser.add_argument("--notes", type=pathlib.Path, default=None,
                        help="with --write-results: a Markdown file whose text follows the table (the reading of it)")
    args = parser.parse_args()
    if args.write_results is not None:
        from _results import write_section

        coarse, fine = (json.loads((d / "summary.json").read_text()) for d in args.write_results)
        notes = "" if args.notes is None else "\n" + args.notes.read_text()
        write_section(SECTION, _section(coarse, fine) + notes)
        return
    run(args)


def run(args):
    args.out.mkdir(parents=True, exist_ok=True)
    start_all = time.perf_counter()
    case = fj.cases.slider_crank(args.nx, args.ny, args.modes, args.t1)
    grid = case.design.mesh
    x_min = case.material.x_min
    if args.filter_length is None:
        filt = fj.DensityFilter(case.design, args.filter_radius)
        filter_m = args.filter_radius * grid.dx
    else:
        filt = fj.DensityFilter(case.design, args.filter_length, scale=(1.0, 1.0))
        filter_m = args.filter_length
    projection = fj.HeavisideProjection(0.5, x_min=x_min, eta_eroded=args.eta_eroded, eta_dilated=args.eta_dilated,
                                         objective=args.robust_objective)
    fun = fj.make_objective(case, filter=filt, projection=projection, rtol=args.rtol)
    volume = fj.VolumeConstraint(args.volume, x_min=x_min, filter=filt, projection=projection)
    setup_s = time.perf_counter() - start_all

    # Each gradient call's time and the wall time since the run started go to <out>/gradient_calls.txt as they
    # happen, so that a killed and resumed run still reports where all its time went.
    calls_file = args.out / "gradient_calls.txt"
    args.resume = args.resume or args.force_resume
    earlier = np.loadtxt(calls_file, ndmin=2) if args.resume and calls_file.exists() else np.zeros((0, 2))
    if not args.resume:
        calls_file.write_text("")
    wall_before = float(earlier[-1, 0]) if len(earlier) else 0.0
    calls = [float(c) for c in earlier[:, 1]]
    started = []

    def timed_fun(x, beta):
        start = time.perf_counter()
        value, grad = jax.block_until_ready(fun(x, beta))
        calls.append(time.perf_counter() - start)
        with calls_file.open("a") as f:
            f.write(f"{wall_before + time.perf_counter() - started[0]:.3f} {calls[-1]:.3f}\n")
        return value, grad

    for name in ("projection", "compiles_itself", "design_size", "fingerprint"):
        setattr(timed_fun, name, getattr(fun, name))

    schedule = fj.beta_continuation(args.beta_start, args.beta_max, every=args.beta_every)
    config = {"nx": args.nx, "ny": args.ny, "modes": args.modes, "t1": args.t1, "volume": args.volume,
              "filter_m": filter_m, "beta_start": args.beta_start, "beta_max": args.beta_max,
              "beta_every": args.beta_every, "rtol": args.rtol}
    if projection.robust:
        config.update(eta_eroded=args.eta_eroded, eta_dilated=args.eta_dilated, robust_objective=args.robust_objective)
    if args.force_resume:
        # The checkpoint's settings stand for its steps; the new ones (e.g. a higher beta_max) act from it on.
        config = json.loads(str(np.load(args.out / "run" / "checkpoint.npz")["config"]))
    x0 = case.initial_design(args.volume) if args.start_from is None else _mapped_design(case, args.start_from)
    if args.start_from is not None:
        config["start_from"] = str(args.start_from)
    start = time.perf_counter()
    started.append(start)
    result = fj.optimize(timed_fun, x0, fj.MMA(x_min), volume, iterations=args.iters, progress=True,
                         beta=schedule, directory=args.out / "run", resume=args.resume or args.force_resume, checkpoint_every=5,
                         force_resume=args.force_resume,
                         config=config)
    run_s = wall_before + time.perf_counter() - start
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

    # The optimiser's design thresholded at eta = 0.5 (0/1 by construction): how much of psi the grey part carried.
    x_01 = np.where(x_phys > 0.5, 1.0, x_min)
    psi_01 = float(fj.objective(case, x_01, rtol=1e-10, atol=1e-12))
    layout = np.asarray(case.design.element_densities(x_phys)).reshape(args.ny, args.nx)
    summary = {
        "mesh": f"{args.nx} x {args.ny}", "nx": args.nx, "ny": args.ny, "n_design": int(case.n_design),
        "modes": args.modes, "t1": args.t1, "filter_length_m": filter_m,
        "filter_radius_elements": filter_m / grid.dx, "beta_start": args.beta_start, "beta_max": args.beta_max,
        "beta_every": args.beta_every, "iterations": int(h.steps), "beta_last": beta_last,
        "steps_at_beta_max": int(sum(schedule(k) == args.beta_max for k in range(h.steps))),
        "gradient_calls": len(calls), "resumed": args.resume,
        "wall_time_s": run_s, "setup_s": setup_s, "first_gradient_s": calls[0] if calls else float("nan"),
        "later_gradients_s": float(np.sum(calls[1:])), "median_later_gradient_s": float(np.median(calls[1:])),
        "fe_stage_per_call_s": fe_s, "optimizer_and_driver_s": run_s - float(np.sum(calls)),
        "psi_optimised": psi_opt, "psi_uniform": psi_uniform, "ratio": psi_opt / psi_uniform,
        "volume": float(x_phys.mean()), "grey_share": float(fj.grey_share(x_phys)), "back_offs": result.back_offs,
        "feasible": bool(result.feasible), "last_max_change": float(h.change[-1]),
        "grey_on_edges": _grey_on_edges(layout), "psi_thresholded": psi_01,
        "ratio_thresholded": psi_01 / float(fj.objective(case, case.initial_design(float(x_01.mean())), rtol=1e-10,
                                                            atol=1e-12)),
        "volume_thresholded": float(x_01.mean()),
        "final_evaluation_s": evaluation_s, "load_average": list(__import__("os").getloadavg()),
        "grey_history": [float(g) for g in h.grey], "psi_history": [float(v) for v in h.value],
        "change_history": [float(c) for c in h.change],
    }
    if projection.robust:
        summary["robust"] = robust_check(case, filt, projection, result.x, beta_last)
    summary["member_size"] = member_size(layout)
    if args.coarse is not None:
        coarse_layout = np.load(args.coarse / "design.npz")["layout"]
        summary["refinement"] = refinement_check(layout, coarse_layout)
        summary["refinement"]["coarse"] = str(args.coarse)
        _plot_refinement(layout, coarse_layout, grid).savefig(args.out / "refinement.png", dpi=150)
    if args.resume and not len(calls) and (args.out / "summary.json").exists():
        # Post-processed again without new steps: keep the timings of the process that ran the steps.
        earlier_summary = json.loads((args.out / "summary.json").read_text())
        for key in ("wall_time_s", "setup_s", "first_gradient_s", "later_gradients_s", "median_later_gradient_s",
                    "optimizer_and_driver_s", "gradient_calls", "load_average"):
            if key in earlier_summary:
                summary[key] = earlier_summary[key]
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    np.savez_compressed(args.out / "design.npz", x=np.asarray(result.x), x_phys=x_phys, layout=layout)
    ax = fj.plot_design(case, x_phys, title=f"reference rod {args.nx} x {args.ny}, MMA + continuation to beta "
                                             f"{beta_last:g}, {h.steps} steps, V = {x_phys.mean():.3f}, "
                                             f"grey {100 * summary['grey_share']:.1f} %")
    ax.figure.set_size_inches(12, 2.4)
    ax.figure.savefig(args.out / "design.png", dpi=150)
    ax = fj.plot_history(h)
    ax.figure.savefig(args.out / "convergence.png", dpi=150)
    print(json.dumps({k: v for k, v in summary.items() if not k.endswith("history")}, indent=2))


def _mapped_design(case, folder):
    """The design variables of the run in `folder` (another mesh of the same rod) on `case`'s design elements: each
    takes the value of the nearest coarse design element (by centroid)."""
    from scipy.spatial import cKDTree

    coarse = json.loads((folder / "summary.json").read_text())
    coarse_case = fj.cases.slider_crank(coarse["nx"], coarse["ny"], coarse["modes"], coarse["t1"])
    nearest = cKDTree(np.asarray(coarse_case.design.domain.design_centroids())).query(
        np.asarray(case.design.domain.design_centroids()))[1]
    return np.asarray(np.load(folder / "design.npz")["x"])[nearest]


def robust_check(case, filt, projection, x, beta) -> dict:
    """psi (rtol 1e-10), volume and grey share of the eroded, blueprint and dilated designs of the final `x`: whether
    the eroded design is the worst case (`psi(eroded) >= psi(blueprint) >= psi(dilated)`), the premise of
    evaluating the objective on the eroded design only."""
    out = {}
    for name, x_phys in zip(("eroded", "blueprint", "dilated"), projection.designs(filt(x), beta)):
        try:
            psi = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
        except fj.SimulationError as error:  # a design too soft to assemble or to run through the motion
            psi, out[f"{name}_error"] = float("nan"), str(error)[:200]
        out[name] = {"psi": psi, "volume": float(np.mean(x_phys)), "grey_share": float(fj.grey_share(x_phys))}
    psi = [out[name]["psi"] for name in ("eroded", "blueprint", "dilated")]
    out["eroded_is_worst"] = bool(psi[0] >= psi[1] >= psi[2])
    out["worst"] = ("eroded", "blueprint", "dilated")[int(np.nanargmax(psi))]
    return out


def member_size(layout) -> dict:
    """The smallest solid and void feature of the layout thresholded at 0.5, in elements: for k = 1, 2, ... the share
    of the solid (void) elements that lie in no all-solid (all-void) k x k square (a morphological opening); the
    largest k with none such is the minimum member (hole) size. The domain's outside counts as void (a flange along
    the edge is as thin as it is inside the domain; a void reaching the edge is open to the outside)."""
    from scipy.ndimage import binary_opening

    out = {}
    for name, mask, pad in (("solid", layout > 0.5, False), ("void", layout <= 0.5, True)):
        padded = np.pad(mask, 6, constant_values=pad)
        thin = []
        for k in range(1, 7):
            opened = binary_opening(padded, structure=np.ones((k, k), bool))[6:-6, 6:-6]
            thin.append(float((mask & ~opened).sum() / max(mask.sum(), 1)))
        out[name] = {"share_not_in_k_square": thin,
                     "min_size": max([k for k, t in zip(range(1, 7), thin) if t == 0.0], default=0)}
    return out


def _grey_on_edges(layout) -> float:
    """The share of grey elements (0.1 < x < 0.9) that have a solid (>= 0.9) and a void (<= 0.1) element within
    two elements: grey edges of members, against grey members (struts as thin as the filter) and grey regions."""
    grey = (layout > 0.1) & (layout < 0.9)
    if not grey.any():
        return float("nan")
    from scipy.ndimage import maximum_filter

    near_solid = maximum_filter((layout >= 0.9).astype(float), size=5) > 0
    near_void = maximum_filter((layout <= 0.1).astype(float), size=5) > 0
    return float((grey & near_solid & near_void).sum() / grey.sum())


def refinement_check(fine, coarse) -> dict:
    """Compare the fine layout `(ny, nx)` with the coarse one `(ny / 2, nx / 2)` mapped onto it (2 x 2 each).

    Both are thresholded at 0.5 (solid where `x_phys > 0.5`); on the uniform grid every element has the same
    area, so the share of elements that differ is the share of the area.
    """
    if fine.shape != (2 * coarse.shape[0], 2 * coarse.shape[1]):
        raise ValueError(f"The coarse layout {coarse.shape} is not half the fine one {fine.shape} per direction; "
                         "run the coarse mesh with nx / 2, ny / 2.")
    from scipy.ndimage import maximum_filter, minimum_filter

    mapped = np.kron(coarse, np.ones((2, 2)))
    differ = (fine > 0.5) != (mapped > 0.5)
    # Within one coarse element (two fine ones) of an edge of the coarse layout, a difference is an edge that sits
    # elsewhere by up to the coarse mesh's resolution; outside that band a member or hole moved, appeared or vanished.
    solid = (mapped > 0.5).astype(int)
    band = maximum_filter(solid, size=5) != minimum_filter(solid, size=5)
    return {"area_differing": float(differ.mean()), "elements_differing": int(differ.sum()),
            "area_differing_off_edges": float((differ & ~band).mean()), "edge_band_area": float(band.mean()),
            "solid_share_fine": float((fine > 0.5).mean()), "solid_share_coarse": float((mapped > 0.5).mean())}


def _plot_refinement(fine, coarse, grid):
    """Three panels: the coarse layout on the fine mesh, the fine layout, and where they differ (x_phys > 0.5)."""
    from matplotlib.figure import Figure

    mapped = np.kron(coarse, np.ones((2, 2)))
    differ = (fine > 0.5) != (mapped > 0.5)
    figure = Figure(figsize=(12, 5.4), layout="constrained")
    extent = (0.0, grid.length, -grid.height / 2, grid.height / 2)
    panels = ((mapped, f"{coarse.shape[1]} x {coarse.shape[0]}, mapped 2 x 2", "Greys"),
              (fine, f"{fine.shape[1]} x {fine.shape[0]}", "Greys"),
              (differ, f"thresholded at 0.5, differing: {100 * differ.mean():.1f} % of the area", "Reds"))
    for ax, (field, title, cmap) in zip(figure.subplots(3, 1, sharex=True), panels):
        ax.imshow(field, origin="lower", extent=extent, cmap=cmap, vmin=0, vmax=1, aspect="auto",
                  interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_ylabel("y [m]")
    ax.set_xlabel("x [m]")
    return figure


def _section(c, f) -> str:
    def row(name, fmt):
        return f"| {name} | {fmt(c)} | {fmt(f)} |"

    def cmd(s):
        return (f"`python benchmarks/bench_time_to_design.py --nx {s['nx']} --ny {s['ny']} --iters {s['iterations']} "
                f"--filter-length {s['filter_length_m']:g} --beta-max {s['beta_max']:g} --beta-every "
                f"{s['beta_every']} --out benchmarks/results/time_to_design_{s['nx']}x{s['ny']}"
                + (f" --coarse benchmarks/results/time_to_design_{c['nx']}x{c['ny']}" if "refinement" in s else "")
                + "`")

    r = f.get("refinement", {})
    return "\n".join([
        cmd(c) + ", then " + cmd(f) + ". The reference rod (t1 = 3 s, 6 modes, default gradient route, rtol 1e-8 in "
        f"the loop), `fj.optimize` with `fj.MMA()`'s defaults (move 0.2, capped under the projection), a cone filter "
        f"of radius {c['filter_length_m']:g} m on both meshes, the Heaviside projection (eta 0.5) with "
        f"`fj.beta_continuation({c['beta_start']:g}, {c['beta_max']:g}, every={c['beta_every']})`, volume <= 0.5. psi "
        "at the paper's forward tolerances (rtol 1e-10, atol 1e-12) against the uniform design of the same volume.",
        "",
        "| quantity | coarse | fine |",
        "|---|---:|---:|",
        row("mesh, densities", lambda s: f"{s['mesh']}, {s['n_design']:,}"),
        row("filter radius (elements)", lambda s: f"{s['filter_length_m']:g} m ({s['filter_radius_elements']:.0f})"),
        row("iterations (steps at beta = max)", lambda s: f"{s['iterations']} ({s['steps_at_beta_max']})"),
        row("wall time of the run", lambda s: f"{s['wall_time_s']:.0f} s"),
        row("first gradient call (with compile)", lambda s: f"{s['first_gradient_s']:.0f} s"),
        row("later gradient calls: sum; median each",
            lambda s: f"{s['later_gradients_s']:.0f} s; {s['median_later_gradient_s']:.1f} s"),
        row("of which the FE stage (timed alone x calls)",
            lambda s: f"{s['fe_stage_per_call_s'] * s['gradient_calls']:.0f} s "
                      f"({s['fe_stage_per_call_s']:.2f} s each)"),
        row("MMA, constraints, projection, driver", lambda s: f"{s['optimizer_and_driver_s']:.0f} s"),
        row("psi / psi(uniform, same volume)", lambda s: f"{s['ratio']:.3f}"),
        row("volume fraction (bound 0.5)", lambda s: f"{s['volume']:.3f}"),
        row("grey share (0.1 < x_phys < 0.9)", lambda s: f"**{100 * s['grey_share']:.1f} %**"),
        row("of the grey elements: on a member's edge (solid and void within 2 elements)",
            lambda s: f"{100 * s['grey_on_edges']:.0f} %"),
        row("thresholded at 0.5 (0/1): psi / psi(uniform), volume",
            lambda s: f"{s['ratio_thresholded']:.3f}, {s['volume_thresholded']:.3f}"),
        row("largest change in the last step", lambda s: f"{s['last_max_change']:.3g}"),
        row("steps redone (back-offs), feasible", lambda s: f"{s['back_offs']}, {'yes' if s['feasible'] else 'no'}"),
        row("load average at the end (1/5/15 min)", lambda s: ", ".join(f"{v:.1f}" for v in s["load_average"])),
        "",
        (f"Refinement check: the {c['mesh']} design mapped onto the {f['mesh']} mesh (each coarse element = 2 x 2 "
         f"fine ones), both thresholded at x_phys = 0.5, differ on **{100 * r['area_differing']:.1f} %** of the area "
         f"(solid share {100 * r['solid_share_coarse']:.1f} % coarse, {100 * r['solid_share_fine']:.1f} % fine)."
         if r else "Refinement check: not run."),
    ]) + "\n"


if __name__ == "__main__":
    main()
