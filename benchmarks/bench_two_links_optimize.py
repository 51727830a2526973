"""The worked example of issue 14: coupler and rocker of a crank–rocker optimised together.

`fj.cases.four_bar_two_links(nx, ny, modes, t1)`: both rods flexible and designed, objective the sum of
both rods' integral compliances. The designs are stacked into one vector for the optimisation loop
(`fj.StackedDesigns`), each rod has its own density filter (`fj.StackedFilter`, radius in element
sizes), and the volume is either shared (`--volume V`: the area fraction of both rods together,
one `fj.VolumeConstraint`) or one per body (`--volume-per-body Vc Vr`: `fj.VolumePerBody`). Adam on
the exact adjoint gradient, the projection onto the volume after every step, the driver's log and
checkpoints in `--out`.

At the end: psi of the optimised physical designs and of the uniform designs of the same volume per
body (rtol 1e-10, atol 1e-12), their ratio, the volume per body, the share of intermediate densities
(`0.1 < x_phys < 0.9`) per body, the wall time; pictures of both optimised rods. Writes `OUT/summary.json`,
`OUT/two_links.png`, `OUT/convergence.png` and the RESULTS.md section "Two links optimised together".

Usage (from the worktree root):
`PYTHONPATH=$PWD flock /tmp/ffr_bench.lock nice python benchmarks/bench_two_links_optimize.py --iters 40`.
"""

import argparse
import json
import os
import pathlib
import sys
import time

import jax.numpy as jnp
import numpy as np
import optax

import ffr_jax as fj

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _results import machine, write_section  # noqa: E402


def plot_two_links(case, x_phys: dict, path, title=""):
    """Both rods' physical densities, one above the other, to scale."""
    from matplotlib.figure import Figure

    names = case.design_map.names
    fig = Figure(figsize=(10, 1.6 * len(names) + 0.6), layout="constrained")
    axes = fig.subplots(len(names), 1)
    for ax, name in zip(np.atleast_1d(axes), names):
        body = case.design_map.bodies[name]
        mesh = body.mesh
        field = np.asarray(body.element_densities(jnp.asarray(x_phys[name]))).reshape(mesh.ny, mesh.nx)
        image = ax.imshow(field, origin="lower", cmap="gray_r", vmin=0.0, vmax=1.0, interpolation="nearest",
                          extent=(0.0, mesh.length, -0.5 * mesh.height, 0.5 * mesh.height), aspect="auto")
        ax.set_xlim(0.0, max(case.design_map.bodies[n].mesh.length for n in names))
        ax.set_ylabel("y [m]")
        ax.set_title(f"{name}: volume {float(np.mean(x_phys[name])):.3f}")
    ax.set_xlabel("x [m]")
    fig.colorbar(image, ax=list(np.atleast_1d(axes)), label="density", fraction=0.03, pad=0.01)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=150)


def summary_table(psi_uniform, psi_opt, volume, grey, wall, steps) -> list[str]:
    """The RESULTS.md table of a two-links optimisation (also used by two_links_summary.py)."""
    return [
        "| quantity | value |",
        "|---|---|",
        f"| psi, uniform designs of the same volume per rod (rtol 1e-10) | {psi_uniform:.6e} |",
        f"| psi, optimised physical designs (rtol 1e-10) | {psi_opt:.6e} |",
        f"| **objective ratio optimised / uniform** | **{psi_opt / psi_uniform:.4f}** |",
        f"| volume coupler / rocker | {volume['coupler']:.4f} / {volume['rocker']:.4f} |",
        f"| grey share (0.1 < x_phys < 0.9) coupler / rocker | {100 * grey['coupler']:.1f} % / {100 * grey['rocker']:.1f} % |",
        f"| wall time ({steps} steps, compile included) | {wall:.0f} s |",
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=40)
    parser.add_argument("--ny", type=int, default=4)
    parser.add_argument("--modes", type=int, default=3)
    parser.add_argument("--t1", type=float, default=1.0)
    parser.add_argument("--iters", type=int, default=40)
    parser.add_argument("--lr", type=float, default=0.05)
    parser.add_argument("--radius", type=float, default=1.5)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--volume-per-body", type=float, nargs=2, metavar=("VC", "VR"))
    parser.add_argument("--rtol", type=float, default=1e-8)
    parser.add_argument("--atol", type=float, default=1e-12)
    parser.add_argument("--out", default="benchmarks/results/two_links_optimize")
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()
    out = pathlib.Path(args.out)

    case = fj.cases.four_bar_two_links(args.nx, args.ny, args.modes, args.t1)
    layout = fj.StackedDesigns(case.design_map)
    filt = fj.StackedFilter.of(case.design_map, args.radius)
    if args.volume_per_body:
        volumes = dict(zip(("coupler", "rocker"), args.volume_per_body))
        constraint = fj.VolumePerBody(volumes, x_min=0.01, filter=filt)
    else:
        volumes = {name: args.volume for name in layout.names}
        constraint = fj.VolumeConstraint(args.volume, x_min=0.01, filter=filt)
    def stacked(x):  # the loop's flat vector <-> the case's dict design, at the boundary
        value, grad = fj.value_and_grad(case, layout.unravel(x), "adjoint", rtol=args.rtol, atol=args.atol)
        return value, layout.ravel(grad)

    fun = fj.filtered_objective(stacked, filt)
    config = dict(vars(args), out=None, resume=None)
    load_before = os.getloadavg()
    start = time.perf_counter()
    result = fj.optimize(fun, layout.ravel(case.initial_design(volumes)), optax.adam(args.lr), constraint,
                         iterations=args.iters, directory=out, resume=args.resume, checkpoint_every=10,
                         config=config, progress=True)
    wall = time.perf_counter() - start
    x_phys = layout.unravel(filt(result.x))
    per_body_volume = {name: float(jnp.mean(x_phys[name])) for name in layout.names}  # equal element areas per rod
    uniform = case.initial_design({name: per_body_volume[name] for name in layout.names})
    psi_opt = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    psi_uniform = float(fj.objective(case, uniform, rtol=1e-10, atol=1e-12))
    grey = {name: float(np.mean((np.asarray(v) > 0.1) & (np.asarray(v) < 0.9))) for name, v in x_phys.items()}
    h = result.history
    summary = dict(settings=dict(nx=args.nx, ny=args.ny, modes=args.modes, t1=args.t1, iters=args.iters, lr=args.lr,
                                 radius=args.radius, volumes=volumes, per_body=bool(args.volume_per_body),
                                 rtol=args.rtol, atol=args.atol),
                   sizes=case.design_map.design_sizes, psi_first=float(h.value[0]), psi_last_step=float(h.value[-1]),
                   psi_opt=psi_opt, psi_uniform=psi_uniform, ratio=psi_opt / psi_uniform,
                   volume_per_body=per_body_volume, grey_0_1_0_9=grey, wall_time_s=wall, machine=machine(),
                   load_before=load_before)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    np.savez(out / "design.npz", x=np.asarray(result.x), **{f"x_phys_{k}": np.asarray(v) for k, v in x_phys.items()})
    plot_two_links(case, x_phys, out / "two_links.png",
                   title=f"crank–rocker, coupler and rocker optimised together: psi / psi_uniform = {psi_opt / psi_uniform:.3f}")
    ax = fj.plot_history(h)
    ax.figure.savefig(out / "convergence.png", dpi=150)
    print(json.dumps(summary, indent=1))
    command = ("PYTHONPATH=$PWD flock /tmp/ffr_bench.lock nice python benchmarks/bench_two_links_optimize.py "
               f"--nx {args.nx} --ny {args.ny} --modes {args.modes} --t1 {args.t1} --iters {args.iters} --lr {args.lr} "
               + (f"--volume-per-body {args.volume_per_body[0]} {args.volume_per_body[1]}" if args.volume_per_body
                  else f"--volume {args.volume}") + f" --out {args.out}")
    body = "\n".join([
        f"`{command}`",
        "",
        f"`fj.cases.four_bar_two_links({args.nx}, {args.ny}, {args.modes}, t1={args.t1})`: crank–rocker, coupler "
        f"({case.design_map.design_sizes['coupler']} densities) and rocker ({case.design_map.design_sizes['rocker']}) "
        "both flexible and designed, objective the sum of both rods' integral compliances. One stacked design "
        f"vector, a density filter per rod (radius {args.radius} elements), "
        + ("one volume constraint per rod " + str(volumes) if args.volume_per_body else
           f"one shared volume constraint V = {args.volume} (area fraction of both rods together)")
        + f", Adam (lr {args.lr}) on the adjoint gradient (rtol {args.rtol}, atol {args.atol}), {args.iters} steps.",
        "",
        *summary_table(psi_uniform, psi_opt, per_body_volume, grey, wall, args.iters),
        "",
        f"Pictures: `{args.out}/two_links.png` (both optimised rods), `{args.out}/convergence.png`.",
        f"Machine: {machine()}; load before the run {', '.join(f'{v:.1f}' for v in load_before)} — the 2-core "
        "machine was shared with other sessions, so the wall time is inflated.",
    ])
    write_section("Two links optimised together", body)


if __name__ == "__main__":
    main()
