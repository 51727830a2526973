"""Kane, Ryan and Banerjee's spin-up beam in space (issue 26): the solid H11 beam of `ffr_jax.cases.spin_up_beam`
against an independent Rayleigh–Ritz model (`tests/spin_up_reference.py`), with and without geometric stiffening.

Kane et al. publish the tip deflections only as curves, so the reference is the Ritz model of the same beam (NumPy/
SciPy, clamped-free eigenfunctions, DOP853 at rtol 1e-11): with as many Ritz functions per direction as the FE
body has mode pairs (the same truncation, so the difference is the FE discretisation and the floating frame's
second-order terms) and with 12 (converged: the truncation error of the FE body's modal basis).

Chordwise (in the plane of rotation) tip deflection `v`, flapwise (along the spin axis, under gravity) `w`, both in
the hub frame. Without stiffening the chordwise motion diverges once the spin exceeds the first bending frequency
(3.80 rad/s, at t ~ 7.9 s); there the comparison stops when the Ritz `|v|` first exceeds 1 m (beyond that the
linear Ritz model and the floating frame, whose second-order inertia terms couple the directions, part ways).

    python benchmarks/bench_spin_up_beam.py [--nx 20 40 80] [--modes 6] [--t1 20]

Writes benchmarks/results/spin_up_beam.json and prints the table of benchmarks/RESULTS.md ("Spin-up beam").
"""

import argparse
import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

sys.path.insert(0, str(pathlib.Path(__file__).parent.parent / "tests"))
import spin_up_reference as ritz  # noqa: E402

HERE = pathlib.Path(__file__).parent


def fe_tip(nx, n_modes, t1, ts, stiffening, rtol):
    t0 = time.perf_counter()
    problem = fj.cases.spin_up_beam(nx, n_modes, t1, stiffening=stiffening)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj = fj.simulate(problem, ts=jnp.asarray(ts), rtol=rtol, atol=1e-2 * rtol)
    jax.block_until_ready(traj.positions)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    traj = fj.simulate(problem, ts=jnp.asarray(ts), rtol=rtol, atol=1e-2 * rtol)
    jax.block_until_ready(traj.positions)
    run = time.perf_counter() - t0
    tip = np.asarray(traj.positions)[:, 7:] @ np.asarray(problem.scene.bodies[0].data.marker_modes[1]).T
    return tip, dict(build_s=build, compile_and_run_s=first, run_s=run)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, nargs="+", default=[20, 40, 80])
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--t1", type=float, default=20.0)
    parser.add_argument("--rtol", type=float, default=1e-10)
    args = parser.parse_args()
    ts = np.linspace(0.0, args.t1, int(round(args.t1 / 0.05)) + 1)
    rows = []
    for stiffening in (True, False):
        refs = {}
        for n in (args.modes // 2, 12):
            beam = ritz.RitzBeam(n, **ritz.KANE_BEAM)
            refs[n] = beam.tip_deflections(ts, stiffening=stiffening, gravity=9.81, **ritz.KANE_SPIN_UP)
        v12 = refs[12][0]
        window = ts <= ts[np.argmax(np.abs(v12) > 1.0)] if np.any(np.abs(v12) > 1.0) else np.ones_like(ts, bool)
        for nx in args.nx:
            tip, cost = fe_tip(nx, args.modes, args.t1, ts, stiffening, args.rtol)
            row = dict(stiffening=stiffening, nx=nx, n_modes=args.modes, t_compared=float(ts[window][-1]), **cost)
            for name, k in (("v", 1), ("w", 2)):
                for n, ref in refs.items():
                    r = ref[0] if name == "v" else ref[1]
                    row[f"max_err_{name}_ritz{n}"] = float(np.max(np.abs(tip[window, k] - r[window])))
                row[f"peak_{name}"] = float(tip[window, k][np.argmax(np.abs(tip[window, k]))])
                row[f"peak_{name}_ritz12"] = float((v12 if name == "v" else refs[12][1])[window][
                    np.argmax(np.abs((v12 if name == "v" else refs[12][1])[window]))])
            row["max_axial_tip"] = float(np.max(np.abs(tip[window, 0])))
            rows.append(row)
            print(json.dumps(row), flush=True)
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / "spin_up_beam.json").write_text(json.dumps(dict(args=vars(args), rows=rows), indent=1))
    n = args.modes // 2
    print(f"\n| stiffening | nx | compared to t (s) | peak v (m) FE / Ritz-12 | max dv vs Ritz-{n} / Ritz-12 (m) | "
          f"peak w (m) FE / Ritz-12 | max dw vs Ritz-{n} / Ritz-12 (m) | build / compile+run / run (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {'yes' if r['stiffening'] else 'no'} | {r['nx']} | {r['t_compared']:.2f} | "
              f"{r['peak_v']:.4f} / {r['peak_v_ritz12']:.4f} | {r[f'max_err_v_ritz{n}']:.1e} / {r['max_err_v_ritz12']:.1e} | "
              f"{r['peak_w']:.4f} / {r['peak_w_ritz12']:.4f} | {r[f'max_err_w_ritz{n}']:.1e} / {r['max_err_w_ritz12']:.1e} | "
              f"{r['build_s']:.1f} / {r['compile_and_run_s']:.1f} / {r['run_s']:.1f} |")


if __name__ == "__main__":
    main()
