"""Summary of an `ffr-jax optimize four-bar-two-links` run (issue 14's worked example, MMA).

Reads `RUN/design.npz` (the CLI's output: settings, both rods' physical densities, psi history),
rebuilds the case from the run's settings and reports: psi of the optimised physical designs and of
uniform designs of the same volume per rod (both at rtol 1e-10, atol 1e-12), their ratio, the volume
per rod, the share of intermediate densities (0.1 < x_phys < 0.9) per rod, and the wall time passed
with `--wall` (measured around the CLI command). Writes `RUN/summary.json` and the RESULTS.md section
"Two links optimised together (MMA, CLI)".

Usage: `python benchmarks/two_links_summary.py RUN --wall SECONDS --command "the CLI command as run"`
"""

import argparse
import json
import pathlib
import sys

import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _results import machine, write_section  # noqa: E402
from bench_two_links_optimize import summary_table  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run")
    parser.add_argument("--wall", type=float, required=True)
    parser.add_argument("--command", required=True)
    args = parser.parse_args()
    run = pathlib.Path(args.run)
    saved = np.load(run / "design.npz")
    s = json.loads(str(saved["config"]))
    case = fj.cases.four_bar_two_links(int(s["nx"]), int(s["ny"]), int(s["modes"]), float(s["t1"]))
    names = case.design_map.names
    x_phys = {name: jnp.asarray(saved[f"x_phys_{name}"]) for name in names}
    volume = {name: float(jnp.mean(x_phys[name])) for name in names}  # equal element areas per rod
    uniform = case.initial_design(volume)
    psi_opt = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    psi_uniform = float(fj.objective(case, uniform, rtol=1e-10, atol=1e-12))
    grey = {name: float(np.mean((np.asarray(v) > 0.1) & (np.asarray(v) < 0.9))) for name, v in x_phys.items()}
    psi = np.asarray(saved["psi"])
    summary = dict(settings=s, sizes=case.design_map.design_sizes, psi_opt=psi_opt, psi_uniform=psi_uniform,
                   ratio=psi_opt / psi_uniform, volume_per_body=volume, grey_0_1_0_9=grey, steps=int(psi.size),
                   psi_first=float(psi[0]), psi_last=float(psi[-1]), wall_time_s=args.wall, machine=machine())
    (run / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))
    bound = (f"one volume bound per rod {s['volume_per_body']}" if s.get("volume_per_body") else
             f"one shared volume bound V = {s['volume']} (area fraction of both rods together)")
    body = "\n".join([
        f"`{args.command}` (wall time measured around it), then `python benchmarks/two_links_summary.py {args.run} ...`.",
        "",
        f"`fj.cases.four_bar_two_links({s['nx']}, {s['ny']}, {s['modes']}, t1={s['t1']})`: coupler "
        f"({case.design_map.design_sizes['coupler']} densities) and rocker ({case.design_map.design_sizes['rocker']}) both "
        f"flexible and designed, objective the sum of both rods' integral compliances; MMA (move {s['mma_move']}) on the "
        f"adjoint gradient (rtol {s['rtol']}, atol {s['atol']}), a density filter per rod (radius {s['filter_radius']} "
        f"elements), {bound}; {psi.size} steps.",
        "",
        *summary_table(psi_uniform, psi_opt, volume, grey, args.wall, psi.size),
        f"| psi at the first / last step (rtol {s['rtol']}) | {psi[0]:.4e} / {psi[-1]:.4e} |",
        "",
        f"Pictures: `{args.run}/design.png` (both optimised rods), `{args.run}/convergence.png`.",
        f"Machine: {machine()}.",
    ])
    write_section("Two links optimised together (MMA, CLI)", body)


if __name__ == "__main__":
    main()
