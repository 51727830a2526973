"""Time to a design for the link example and the two links (issue 30): MMA, a filter in metres, continuation.

Two examples, one command each:

- `link`: the holed link as the coupler of a crank–rocker (`fj.cases.link_four_bar`, gmsh mesh of target size
  `--mesh-size`, passive solid rims around both pin holes), objective the coupler's integral compliance.
- `two-links`: coupler and rocker of a crank–rocker designed together (`fj.cases.four_bar_two_links`, coupler
  `--nx` x `--ny` elements, the rocker the same element size), objective the sum of both compliances; one
  dict design, one volume bound shared by both rods.

Both run what a user gets: `fj.optimize` with `fj.MMA()`'s defaults (move 0.2), a `fj.DensityFilter` whose
radius is a physical length (`--filter-length` metres, `scale=(1, 1)`: the same length on a refined mesh),
`fj.HeavisideProjection(0.5)` and the default continuation (no `beta` given: `fj.beta_continuation()`,
1 -> 32 doubled every 10 steps), volume <= `--volume`. Checkpoints every `--checkpoint-every` steps into
`--out`; running the same command again resumes (the steps are deterministic), and every gradient call's time
is appended to `OUT/calls.jsonl` as it happens, so a killed run loses neither design nor timing.

At the end: psi of the final physical design and of the uniform design of the same volume (forward rtol 1e-10),
their ratio, the volume (area fraction), the grey share (`fj.grey_share`, 0.1 < x_phys < 0.9, by area), the
wall time split into gradient calls (the first with compile), the FE stage (modes and body data, timed alone
and multiplied by the number of calls) and the rest (MMA, constraints, projection, driver). With
`--refine-of DIR` (a run of the same example on a coarser mesh with the same `--filter-length`) also the share
of the area where the two designs thresholded at 0.5 differ (each fine element compared with the coarse element
that contains its centroid). Writes `OUT/summary.json`, `OUT/design.png`, `OUT/convergence.png`, `OUT/design.npz`.

Usage (from the worktree root):
```
PYTHONPATH=$PWD nohup python benchmarks/bench_time_to_design_links.py link --mesh-size 0.004 --modes 2 --t1 0.05 \
    --filter-length 0.006 --iters 60 > link.log 2>&1 &
PYTHONPATH=$PWD nohup python benchmarks/bench_time_to_design_links.py two-links --nx 100 --ny 8 --modes 3 --t1 1.0 \
    --filter-length 0.015 --iters 60 > two_links.log 2>&1 &
```
`--eta-eroded 0.7 --eta-dilated 0.3 [--robust-objective max]`: the robust formulation of the projection (eroded,
blueprint and dilated designs; the blueprint reported; `summary.json` then holds psi of all three); `--beta-max`,
`--beta-every`: another continuation than the default; `--beta-start B --start-from DIR`: start from another run's
design variables (DIR, the same example on any mesh: each element takes the nearest element's value by centroid)
at beta B, e.g. the coarse run's last beta: whether its layout is still optimal on this mesh.

RESULTS.md: "Time to a design", subsections of the link and the two links (written by hand from summary.json).
"""

import argparse
import json
import os
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

RESULTS_DIR = pathlib.Path(__file__).parent / "results"


def build(args):
    """`(case, filter, projection, objective, constraint, x0, areas)` of the example (areas: dict or array)."""
    if args.example == "link":
        case = fj.cases.link_four_bar(args.t1, mesh_size=args.mesh_size, n_modes=args.modes)
        x_min = case.material.x_min
        filt = fj.DensityFilter(case.design, args.filter_length, scale=(1.0, 1.0))
        areas = np.asarray(case.design.domain.design_areas())
    else:
        case = fj.cases.four_bar_two_links(args.nx, args.ny, args.modes, args.t1)
        x_min = min(body.material.x_min for body in case.design_map.bodies.values())
        filt = {name: fj.DensityFilter(body, args.filter_length, scale=(1.0, 1.0))
                for name, body in case.design_map.bodies.items()}
        areas = {name: np.asarray(body.domain.design_areas()) for name, body in case.design_map.bodies.items()}
    projection = fj.HeavisideProjection(0.5, x_min=x_min, eta_eroded=args.eta_eroded, eta_dilated=args.eta_dilated,
                                         objective=args.robust_objective)
    fun = fj.make_objective(case, filter=filt, projection=projection, rtol=args.rtol, atol=args.atol)
    constraint = fj.VolumeConstraint(args.volume, x_min=x_min, filter=filt, projection=projection)
    x0 = case.initial_design(args.volume if args.example == "link"
                             else {name: args.volume for name in case.design_map.names})
    return case, filt, projection, fun, constraint, x_min, x0, areas


def area_fraction(x_phys, areas) -> float:
    if isinstance(x_phys, dict):
        return float(sum(areas[n] @ np.asarray(x_phys[n]) for n in x_phys) / sum(areas[n].sum() for n in x_phys))
    return float(areas @ np.asarray(x_phys) / areas.sum())


def fe_stage_seconds(case, x_phys) -> float:
    """Median time of the FE stage alone (modes and body data of every designed body), compiled."""
    if isinstance(x_phys, dict):
        fe = jax.jit(lambda x: [case.design_map.bodies[n].modes(x[n]) for n in x])
    else:
        fe = jax.jit(lambda x: case.modes(x))
    jax.block_until_ready(fe(x_phys))
    times = []
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready(fe(x_phys))
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def centroids(case):
    """`{name: (n_design, 2)}` (or one array) of the design elements' centroids in the body frame."""
    if len(case.design_map.names) > 1:
        return {name: np.asarray(body.domain.design_centroids()) for name, body in case.design_map.bodies.items()}
    return np.asarray(case.design.domain.design_centroids())


def refinement_difference(fine_case, fine_phys, fine_areas, coarse_dir: pathlib.Path, coarse_args):
    """Area share where the fine and the coarse design, thresholded at 0.5, differ (nearest coarse centroid).

    Returns `(share, details)`: `details` (two links, the rods' regular meshes) also holds the share of the area
    that differs outside one coarse element of the coarse layout's edges (there a member or hole moved, appeared or
    vanished; inside it an edge sits elsewhere by up to the coarse resolution, as in `bench_time_to_design.py`'s
    `refinement_check`) and `{name: differing (0/1)}` for a picture.
    """
    from scipy.spatial import cKDTree

    coarse_case = build(coarse_args)[0]
    stored = np.load(coarse_dir / "design.npz")
    fine_c, coarse_c = centroids(fine_case), centroids(coarse_case)
    if isinstance(fine_phys, dict):
        total = sum(a.sum() for a in fine_areas.values())
        differ, off_edges, band_area, maps = 0.0, 0.0, 0.0, {}
        for n in fine_phys:
            mapped = stored[f"x_phys_{n}"][cKDTree(coarse_c[n]).query(fine_c[n])[1]] > 0.5
            d = (np.asarray(fine_phys[n]) > 0.5) != mapped
            # The coarse element's size along each axis; within one of it (Chebyshev, scaled) of a fine element
            # lie both coarse solid and coarse void: the edge band.
            size = np.array([np.diff(np.unique(np.round(coarse_c[n][:, k], 12))).min() for k in range(2)])
            scaled = fine_c[n] / size
            neighbours = cKDTree(scaled).query_ball_point(scaled, r=1.0 + 1e-9, p=np.inf)
            band = np.array([mapped[i].any() and not mapped[i].all() for i in map(np.asarray, neighbours)])
            differ += fine_areas[n] @ d
            off_edges += fine_areas[n] @ (d & ~band)
            band_area += fine_areas[n] @ band
            maps[n] = d.astype(float)
        return float(differ / total), {"area_differing_off_edges": float(off_edges / total),
                                       "edge_band_area": float(band_area / total), "maps": maps}
    nearest = cKDTree(coarse_c).query(fine_c)[1]
    return (float(fine_areas @ ((np.asarray(fine_phys) > 0.5) != (stored["x_phys"][nearest] > 0.5))
                  / fine_areas.sum()), {})


def mapped_design(case, folder: pathlib.Path, args):
    """The design variables of the run in `folder` (the same example, another mesh) on `case`'s design elements,
    flattened as `x0` is: each element takes the value of the nearest element of that run (by centroid)."""
    from jax.flatten_util import ravel_pytree
    from scipy.spatial import cKDTree

    other = json.loads((folder / "summary.json").read_text())["settings"]
    other_case = build(argparse.Namespace(**{**vars(args), **other, "start_from": None}))[0]
    stored = np.load(folder / "design.npz")
    here, there = centroids(case), centroids(other_case)
    if isinstance(here, dict):
        return {n: np.asarray(stored[f"x_{n}"])[cKDTree(there[n]).query(here[n])[1]] for n in here}
    return np.asarray(stored["x"])[cKDTree(there).query(here)[1]]


def robust_check(case, filt, projection, x, beta, areas, atol) -> dict:
    """psi (rtol 1e-10), volume and grey share of the eroded, blueprint and dilated designs of the final `x` (dicts
    by body for the two links): which is the worst case."""
    if isinstance(x, dict):
        per_body = {n: projection.designs(filt[n](x[n]), beta) for n in x}
        designs = [{n: np.asarray(per_body[n][i]) for n in x} for i in range(3)]
    else:
        designs = [np.asarray(d) for d in projection.designs(filt(x), beta)]
    out = {}
    for name, x_phys in zip(("eroded", "blueprint", "dilated"), designs):
        try:
            psi = float(fj.objective(case, x_phys, rtol=1e-10, atol=atol))
        except fj.SimulationError as error:
            psi, out[f"{name}_error"] = float("nan"), str(error)[:200]
        out[name] = {"psi": psi, "volume": area_fraction(x_phys, areas),
                     "grey_share": float(fj.grey_share(x_phys, areas=areas))}
    psi = [out[n]["psi"] for n in ("eroded", "blueprint", "dilated")]
    out["worst"] = ("eroded", "blueprint", "dilated")[int(np.nanargmax(psi))]
    return out


def main():
    # As the ffr-jax command does, before JAX starts its backend: XLA's concurrency-optimised CPU scheduler off. A run
    # of bench_time_to_design_links.py without it hung once for 5 minutes at 0 % CPU in the Lanczos modal analysis's
    # host callback while building a case (benchmarks/RESULTS.md, "The two links", trap); with it, the same command ran.
    from ffr_jax._dynamics._xla_flags import avoid_batched_lapack_deadlock

    avoid_batched_lapack_deadlock()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("example", choices=["link", "two-links"])
    parser.add_argument("--mesh-size", type=float, default=0.004, help="link: gmsh target element size [m]")
    parser.add_argument("--nx", type=int, default=100, help="two-links: coupler elements along")
    parser.add_argument("--ny", type=int, default=8, help="two-links: elements across")
    parser.add_argument("--modes", type=int, default=2)
    parser.add_argument("--t1", type=float, default=0.05)
    parser.add_argument("--iters", type=int, default=60)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--filter-length", type=float, required=True, help="filter radius in metres")
    parser.add_argument("--rtol", type=float, default=1e-8, help="tolerance of the solves inside the loop")
    parser.add_argument("--atol", type=float, default=None,
                        help="absolute tolerance inside the loop (default: link 1e-15, two-links 1e-12)")
    parser.add_argument("--checkpoint-every", type=int, default=5)
    parser.add_argument("--mma-move", type=float, default=0.2, help="fj.MMA's move limit (default 0.2, its default)")
    parser.add_argument("--beta-start", type=float, default=1.0, help="the continuation's first beta (default 1)")
    parser.add_argument("--start-from", type=pathlib.Path, default=None,
                        help="another run's OUT folder (same example, any mesh): start from its design variables")
    parser.add_argument("--beta-max", type=float, default=32.0, help="the continuation's last beta (fj's default 32)")
    parser.add_argument("--beta-every", type=int, default=10, help="steps between doublings of beta (default 10)")
    parser.add_argument("--eta-eroded", type=float, default=None,
                        help="with --eta-dilated: the robust formulation of the projection")
    parser.add_argument("--eta-dilated", type=float, default=None)
    parser.add_argument("--robust-objective", default="max", choices=("eroded", "blueprint", "dilated", "max"))
    parser.add_argument("--refine-of", type=pathlib.Path, default=None,
                        help="a coarser run's OUT folder: compare the thresholded layouts")
    parser.add_argument("--out", type=pathlib.Path, default=None)
    parser.add_argument("--force-resume", action="store_true", help="passed to fj.optimize (a checkpoint of an "
                        "older version of this script, whose stored settings differ)")
    args = parser.parse_args()
    schedule = fj.beta_continuation(args.beta_start, args.beta_max, every=args.beta_every)
    if args.atol is None:
        args.atol = 1e-15 if args.example == "link" else 1e-12  # link: psi ~ 1e-8, its coordinates ~ 1e-7
    if args.out is None:
        args.out = RESULTS_DIR / f"time_to_design_{args.example.replace('-', '_')}"
    args.out.mkdir(parents=True, exist_ok=True)
    # --iters is left out of the stored settings, so the same command with more steps continues a finished run.
    config = {k: v for k, v in vars(args).items() if k not in ("out", "refine_of", "checkpoint_every", "iters",
                                                             "force_resume")}
    if args.eta_eroded is None and args.beta_max == 32.0 and args.beta_every == 10:
        # The settings of the runs made before these options (their checkpoints resume unchanged).
        for key in ("beta_max", "beta_every", "eta_eroded", "eta_dilated", "robust_objective"):
            config.pop(key)
    for key, default in (("beta_start", 1.0), ("start_from", None), ("mma_move", 0.2)):  # runs made before these options resume
        if config[key] == default:
            config.pop(key)
    if args.start_from is not None:
        config["start_from"] = str(args.start_from)

    start_all = time.perf_counter()
    case, filt, projection, fun, constraint, x_min, x0, areas = build(args)
    if args.start_from is not None:
        x0 = mapped_design(case, args.start_from, args)
    setup_s = time.perf_counter() - start_all
    session = time.time()
    calls_file = args.out / "calls.jsonl"

    def timed_fun(x, beta):
        start = time.perf_counter()
        value, grad = jax.block_until_ready(fun(x, beta))
        with calls_file.open("a") as f:
            f.write(json.dumps({"session": session, "s": time.perf_counter() - start, "beta": float(beta),
                                "psi": float(value)}) + "\n")
        return value, grad

    unravel = None
    if isinstance(x0, dict):
        # fj.optimize flattens a dict design with a wrapper that drops `compiles_itself`, so it would trace this
        # timed function into a program of its own (no timing possible, and the case's kept programs unused):
        # the flattening is done here instead, with the driver's own (internal) constraint wrapper.
        from jax.flatten_util import ravel_pytree

        from ffr_jax._optimize._pytree import Raveled

        x0, unravel = ravel_pytree(x0)
        dict_fun = fun

        def fun(x, beta):
            value, grad = dict_fun(unravel(x), beta)
            return value, ravel_pytree(grad)[0]

        for name in ("projection", "compiles_itself", "fingerprint"):
            setattr(fun, name, getattr(dict_fun, name))
        constraint = Raveled(constraint, unravel)

    for name in ("projection", "compiles_itself", "design_size", "fingerprint"):
        if hasattr(fun, name):
            setattr(timed_fun, name, getattr(fun, name))

    resume = (args.out / "checkpoint.npz").exists()
    load_before = os.getloadavg()
    start = time.perf_counter()
    result = fj.optimize(timed_fun, x0, fj.MMA(x_min, move=args.mma_move), constraint, iterations=args.iters, progress=True,
                         directory=args.out, resume=resume, checkpoint_every=args.checkpoint_every, config=config,
                         beta=schedule,
                         force_resume=args.force_resume)
    session_s = time.perf_counter() - start
    with (args.out / "sessions.jsonl").open("a") as f:
        f.write(json.dumps({"session": session, "run_s": session_s, "setup_s": setup_s, "resumed": resume,
                            "load_before": load_before, "load_after": os.getloadavg()}) + "\n")
    if unravel is not None:
        result = result._replace(x=unravel(result.x))
    h = result.history
    beta_last = schedule(h.steps - 1)
    x_phys = fj.physical_densities(result.x, filt, projection, beta_last)
    x_phys = {n: np.asarray(v) for n, v in x_phys.items()} if isinstance(x_phys, dict) else np.asarray(x_phys)

    fe_s = fe_stage_seconds(case, x_phys)
    volume = area_fraction(x_phys, areas)
    uniform = case.initial_design(volume if args.example == "link" else {n: volume for n in case.design_map.names})
    psi_opt = float(fj.objective(case, x_phys, rtol=1e-10, atol=args.atol))
    psi_uniform = float(fj.objective(case, uniform, rtol=1e-10, atol=args.atol))
    grey = float(fj.grey_share(x_phys, areas=areas))

    calls = [json.loads(line) for line in calls_file.read_text().splitlines()]
    sessions = [json.loads(line) for line in (args.out / "sessions.jsonl").read_text().splitlines()]
    first_per_session = {}
    for c in calls:
        first_per_session.setdefault(c["session"], c["s"])
    first_s = sum(first_per_session.values())
    later = [c["s"] for c in calls if first_per_session[c["session"]] is not c["s"]]
    wall = sum(s["run_s"] for s in sessions)
    summary = {
        "example": args.example, "settings": config,
        "mesh": (f"gmsh {args.mesh_size} m" if args.example == "link"
                 else ", ".join(f"{n} {b.mesh.nx} x {b.mesh.ny}" for n, b in case.design_map.bodies.items())),
        "n_elements": (int(case.mesh.n_elements) if args.example == "link"
                       else {n: int(b.mesh.n_elements) for n, b in case.design_map.bodies.items()}),
        "n_design": (int(case.n_design) if args.example == "link" else dict(case.design_map.design_sizes)),
        "iterations": int(h.steps), "beta_last": beta_last, "gradient_calls": len(calls),
        "sessions": len(sessions), "wall_time_s": wall, "setup_s_last_session": setup_s,
        "first_gradient_per_session_s": first_s, "later_gradients_s": float(np.sum(later)),
        "median_later_gradient_s": float(np.median(later)) if later else None,
        "fe_stage_per_call_s": fe_s, "fe_stage_total_s": fe_s * len(calls),
        "optimizer_and_driver_s": wall - float(sum(c["s"] for c in calls)),
        "psi_optimised": psi_opt, "psi_uniform": psi_uniform, "ratio": psi_opt / psi_uniform,
        "volume": volume, "grey_share": grey,
        "grey_share_per_body": ({n: float(fj.grey_share(v, areas=areas[n])) for n, v in x_phys.items()}
                                if isinstance(x_phys, dict) else None),
        "volume_per_body": ({n: area_fraction({n: v}, areas) for n, v in x_phys.items()}
                            if isinstance(x_phys, dict) else None),
        "back_offs": result.back_offs, "feasible": bool(result.feasible),
        "load": [s["load_before"] for s in sessions], "machine_cpus": os.cpu_count(),
        "grey_history": [float(g) for g in h.grey], "psi_history": [float(v) for v in h.value],
    }
    if projection.robust:
        summary["robust"] = robust_check(case, filt, projection, result.x, beta_last, areas, args.atol)
    if args.refine_of is not None:
        coarse = json.loads((args.refine_of / "summary.json").read_text())["settings"]
        coarse_args = argparse.Namespace(**{**vars(args), **coarse})
        summary["refinement_of"] = str(args.refine_of)
        share, details = refinement_difference(case, x_phys, areas, args.refine_of, coarse_args)
        summary["thresholded_layouts_differ_area_share"] = share
        maps = details.pop("maps", None)
        summary.update(details)
        if maps is not None:
            fj.plot_designs(case, {n: np.where(m > 0, 1.0, x_min) for n, m in maps.items()},
                            title=f"thresholded at 0.5, differing from\n{args.refine_of.name}: {100 * share:.1f} % "
                                  f"of the area, {100 * details['area_differing_off_edges']:.1f} % off the coarse "
                                  "edges").savefig(args.out / "refinement.png", dpi=120)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    if isinstance(x_phys, dict):
        np.savez(args.out / "design.npz", **{f"x_{n}": np.asarray(result.x[n]) for n in x_phys},
                 **{f"x_phys_{n}": v for n, v in x_phys.items()})
        fig = fj.plot_designs(case, x_phys, title=f"two links, MMA + continuation, {h.steps} steps, V = {volume:.3f}, "
                                                  f"psi ratio {psi_opt / psi_uniform:.3f}, grey {100 * grey:.1f} %")
    else:
        np.savez(args.out / "design.npz", x=np.asarray(result.x), x_phys=x_phys)
        ax = fj.plot_design(case, x_phys, title=f"link in a crank–rocker, MMA + continuation, {h.steps} steps, "
                                                f"V = {volume:.3f}, psi ratio {psi_opt / psi_uniform:.3f}, "
                                                f"grey {100 * grey:.1f} %")
        fig = ax.figure
    fig.savefig(args.out / "design.png", dpi=120)
    fj.plot_history(h).figure.savefig(args.out / "convergence.png", dpi=100)
    print(json.dumps({k: v for k, v in summary.items() if not k.endswith("history")}, indent=1))


if __name__ == "__main__":
    main()
