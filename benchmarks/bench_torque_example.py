"""A crank-rocker whose peak driving torque is minimised by the design of its flexible coupler (issue 31).

`fj.cases.four_bar` (rigid crank driven by an angle law, flexible coupler = the designed rod, rigid rocker).
Objective `psi = int tau^P dt` of the crank's `AngleDriver` (`fj.JointLoad(case, "AngleDriver(crank)",
"torque", P)`, P = 8, so that `(psi / T)^(1/P)` approaches the peak |tau|), adjoint gradients, MMA, with
the coupler's volume held at one half (`mean(x_phys) <= 0.5` and its mass >= the mass of the uniform half
design, so the run cannot just remove material), density filter 1.5. At the end: the peak |tau| over 301
output times and the P-norm before (uniform design) and after, and pictures of the design.

A reduced coupler mesh, few modes and few MMA steps (2-core machine): say so where the numbers are quoted.

Usage: `python benchmarks/bench_torque_example.py [--nx 24 --ny 4 --modes 4 --t1 1.5 --iters 20 --out DIR
--directory RUN]` (`--directory`: checkpoints every 5 steps; run again with the same folder to resume a stopped run).
"""

import argparse
import json
import pathlib
import time

import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

OUT = pathlib.Path(__file__).parent / "results" / "torque_example"
RTOL, ATOL = 1e-8, 1e-10
DRIVER = "AngleDriver(crank)"


def torques(case, x_phys, n=301):
    traj = fj.simulate(case, x_phys, ts=jnp.linspace(case.t0, case.t1, n), rtol=1e-10, atol=1e-12)
    return np.asarray(traj.ts), np.asarray(fj.joint_forces(case, traj, x_phys)[DRIVER].torque)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=24)
    parser.add_argument("--ny", type=int, default=4)
    parser.add_argument("--modes", type=int, default=4)
    parser.add_argument("--t1", type=float, default=1.5)
    parser.add_argument("--iters", type=int, default=20)
    parser.add_argument("--power", type=float, default=8.0)
    parser.add_argument("--out", default=str(OUT), help="folder of the pictures and summary.json")
    parser.add_argument("--directory", help="run folder: checkpoints, resumed when it holds one")
    args = parser.parse_args()
    out_dir = pathlib.Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    base = fj.cases.four_bar(args.nx, args.ny, args.modes, args.t1)
    case = base.with_objective(fj.JointLoad(base, DRIVER, "torque", args.power))
    filt = fj.DensityFilter(case.design, 1.5)
    x0 = case.initial_design(0.5)
    mass_half = float(fj.MassConstraint(case.design, 1.0).mass(x0))
    constraints = [fj.VolumeConstraint(0.5, x_min=case.material.x_min, filter=filt),
                   fj.MassConstraint(case.design, mass_half, lower=True, filter=filt)]
    fun = fj.make_objective(case, "adjoint", filter=filt, rtol=RTOL, atol=ATOL)
    start = time.perf_counter()
    run = pathlib.Path(args.directory) if args.directory else None
    result = fj.optimize(fun, x0, fj.MMA(case.material.x_min), constraints, iterations=args.iters, progress=False,
                         directory=run, resume=run is not None and run.exists() and any(run.iterdir()),
                         checkpoint_every=5)
    wall = time.perf_counter() - start
    x_opt = np.asarray(filt(result.x))

    span = case.t1 - case.t0
    out = {}
    curves = {}
    for name, x in (("uniform", np.asarray(x0)), ("optimised", x_opt)):
        psi = float(fj.objective(case, x, rtol=1e-10, atol=1e-12))
        ts, tau = torques(case, x)
        curves[name] = tau
        out[name] = dict(psi=psi, p_norm=(psi / span) ** (1 / args.power), peak_abs_torque=float(np.abs(tau).max()),
                         t_peak=float(ts[np.argmax(np.abs(tau))]), volume=float(np.mean(x)),
                         mass=float(fj.MassConstraint(case.design, 1.0).mass(x)))
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 3.2), layout="constrained")
    ax = figure.subplots()
    for name, tau in curves.items():
        ax.plot(ts, tau, label=f"{name}: peak |tau| {np.abs(tau).max():.3g} N m")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("driving torque [N m]")
    ax.legend()
    figure.savefig(out_dir / "torque.png", dpi=120)
    ax = fj.plot_design(case, x_opt, title="coupler design minimising the peak driving torque (volume 0.5)")
    ax.figure.savefig(out_dir / "density_optimised.png", dpi=120)
    summary = dict(settings=vars(args), **out, peak_ratio=out["optimised"]["peak_abs_torque"] /
                   out["uniform"]["peak_abs_torque"], descriptions=list(result.descriptions),
                   feasible=bool(result.feasible), psi_history=[float(v) for v in result.history.value], wall_s=wall)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
