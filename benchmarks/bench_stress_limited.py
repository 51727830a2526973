"""The rod optimised for compliance under a stress limit (issue 31), with the limit active at the optimum.

1. Compliance-optimal rod: `min psi` (integral compliance, paper eq. 49) with `mean(x_phys) <= 0.5`, density
   filter 1.5, MMA, `--iters` steps from the uniform design.
2. The same with the aggregated stress constraint `sigma_PN(x_phys) <= limit` (`stress_constraint`: the 8-norm
   of the qp-relaxed von Mises stress `x^0.5 E0 D B Phi q` over the Gauss points and the motion), the limit
   `--limit-factor` times sigma_PN of the compliance-optimal rod, so that it is active at the optimum.
At the end: psi of both designs (and the ratio), sigma_PN against the limit, the peak relaxed and
macroscopic von Mises stress (over 201 output times and the Gauss points) and the ratio peak / sigma_PN; the
densities and the peak von Mises fields as pictures (results/stress_limited/).

The rod is reduced (a small mesh, few modes, a short motion, few MMA steps) so that both runs fit a few
minutes on a 2-core machine: say so where the numbers are quoted.

Usage: `python benchmarks/bench_stress_limited.py [--nx 24 --ny 4 --modes 4 --t1 1.0 --iters 25
--limited-iters 40 --limit-factor 0.85 --reuse --out DIR]`. Writes the
RESULTS.md section "Stress-limited rod (issue 31)" (default settings only).
"""

import argparse
import json
import pathlib
import time

import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

OUT = pathlib.Path(__file__).parent / "results" / "stress_limited"
RTOL, ATOL = 1e-8, 1e-10


def run(case, filt, constraints, iters):
    fun = fj.make_objective(case, "adjoint", filter=filt, rtol=RTOL, atol=ATOL)
    start = time.perf_counter()
    result = fj.optimize(fun, case.initial_design(0.5), fj.MMA(case.material.x_min), constraints, iterations=iters,
                         progress=False)
    return result, time.perf_counter() - start


def measure(case, x_phys, limit):
    psi = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    sigma_pn = float(fj.aggregated_stress(case, x_phys, limit, rtol=RTOL, atol=ATOL)[0])
    traj = fj.simulate(case, x_phys, ts=jnp.linspace(case.t0, case.t1, 201), rtol=1e-10, atol=1e-12)
    relaxed = np.asarray(fj.peak_von_mises(case, traj, x_phys, relaxation=0.5))
    macro = np.asarray(fj.peak_von_mises(case, traj, x_phys))
    return dict(psi=psi, sigma_pn=sigma_pn, peak_relaxed=float(relaxed.max()), peak_macro=float(macro.max()),
                volume=float(np.mean(x_phys))), relaxed


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=24)
    parser.add_argument("--ny", type=int, default=4)
    parser.add_argument("--modes", type=int, default=4)
    parser.add_argument("--t1", type=float, default=1.0)
    parser.add_argument("--iters", type=int, default=25)
    parser.add_argument("--limited-iters", type=int, default=40, help="MMA steps of the stress-limited run")
    parser.add_argument("--limit-factor", type=float, default=0.85)
    parser.add_argument("--reuse", action="store_true", help="reuse the stored compliance-optimal design")
    parser.add_argument("--out", default=str(OUT), help="folder of the pictures, the designs and summary.json")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = fj.cases.slider_crank(args.nx, args.ny, args.modes, args.t1)
    filt = fj.DensityFilter(case.design, 1.5)
    volume = fj.VolumeConstraint(0.5, x_min=case.material.x_min, filter=filt)

    stored = out / "compliance_design.npz"
    if args.reuse and stored.exists():
        x_plain, wall_plain = np.load(stored)["x_phys"], float(np.load(stored)["wall_s"])
    else:
        plain, wall_plain = run(case, filt, [volume], args.iters)
        x_plain = np.asarray(filt(plain.x))
        np.savez(stored, x_phys=x_plain, wall_s=wall_plain)
    probe = 1e6  # any normalisation: sigma_PN does not depend on it
    stats_plain, _ = measure(case, x_plain, probe)
    limit = args.limit_factor * stats_plain["sigma_pn"]
    stats_plain, peak_plain = measure(case, x_plain, limit)

    stress = fj.stress_constraint(case, limit, filter=filt, rtol=RTOL, atol=ATOL)
    limited, wall_limited = run(case, filt, [volume, stress], args.limited_iters)
    x_limited = np.asarray(filt(limited.x))
    stats_limited, peak_limited = measure(case, x_limited, limit)

    vmax = max(peak_plain.max(), peak_limited.max())
    for name, x, peak in (("compliance", x_plain, peak_plain), ("stress_limited", x_limited, peak_limited)):
        ax = fj.plot_design(case, x, title=f"{name.replace('_', '-')} design, volume {np.mean(x):.3f}")
        ax.figure.savefig(out / f"density_{name}.png", dpi=120)
        ax = fj.plot_peak_stress(case, peak, limit=limit, vmax=vmax,
                              title=f"peak relaxed von Mises, {name.replace('_', '-')} design")
        ax.figure.savefig(out / f"peak_von_mises_{name}.png", dpi=120)
    summary = dict(settings=vars(args), limit=limit, compliance=stats_plain, stress_limited=stats_limited,
                   psi_ratio=stats_limited["psi"] / stats_plain["psi"],
                   g_final=[float(g) for g in limited.constraints], descriptions=list(limited.descriptions),
                   feasible=bool(limited.feasible), wall_s=[wall_plain, wall_limited])
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
