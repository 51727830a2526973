"""Topology optimisation of the reference rod at 50 % volume, and what it achieved.

Runs `ffr-jax optimize slider-crank` (the CLI, so the run is checkpointed and can be resumed with
the same command: an interrupted benchmark continues where it stopped), then evaluates, at the
paper's forward tolerances (rtol 1e-10, atol 1e-12):

- `psi` of the optimised physical design `H x` and of the uniform design of equal volume;
- the share of intermediate physical densities (`0.1 < x < 0.9`, and `0.05 < x < 0.95`);
- the wall time of the run (from the log's checkpoints: the sum over the sessions that made it).

Usage: `python benchmarks/bench_optimize.py [--iters 40 --optimizer adam --lr 0.05 --out DIR]`
(`--nx/--ny/--modes/--t1` for a smaller case). Writes the section
"Topology optimisation of the reference rod" of RESULTS.md (reference mesh only) and
`DIR/summary.json`, `DIR/design.png`, `DIR/convergence.png`.
"""

import argparse
import json
import pathlib
import time

import numpy as np

import ffr_jax
from ffr_jax._cli import main as cli


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=40)
    parser.add_argument("--optimizer", default="adam", choices=["adam", "oc"])
    parser.add_argument("--lr", type=float, default=0.05)
    parser.add_argument("--filter-radius", type=float, default=1.5)
    parser.add_argument("--rtol", type=float, default=1e-8, help="tolerance of the solves inside the loop")
    parser.add_argument("--nx", type=int, default=100)
    parser.add_argument("--ny", type=int, default=6)
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--t1", type=float, default=3.0)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--out", type=pathlib.Path,
                        default=pathlib.Path(__file__).parent / "results" / "optimize_reference")
    args = parser.parse_args()

    run = ["optimize", "slider-crank", "--iters", str(args.iters), "--no-progress"]
    resume = (args.out / "checkpoint.npz").exists()
    settings = ["--volume", str(args.volume), "--optimizer", args.optimizer, "--filter-radius",
                str(args.filter_radius), "--rtol", str(args.rtol), "--nx", str(args.nx), "--ny", str(args.ny),
                "--modes", str(args.modes), "--t1", str(args.t1)]
    if args.optimizer == "adam":
        settings += ["--lr", str(args.lr)]
    start = time.perf_counter()
    code = cli(run + (["--resume", str(args.out)] if resume else ["--out", str(args.out)]) + settings)
    session_s = time.perf_counter() - start
    if code != 0:
        raise SystemExit(code)
    timing_file = args.out / "wall_time.json"
    sessions = json.loads(timing_file.read_text()) if timing_file.exists() else []
    sessions.append(session_s)
    timing_file.write_text(json.dumps(sessions))

    stored = np.load(args.out / "design.npz")
    x_phys = stored["x_phys"]
    case = ffr_jax.cases.slider_crank(args.nx, args.ny, args.modes, args.t1)
    uniform = case.initial_design(float(np.mean(x_phys)))
    psi_opt = float(ffr_jax.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    psi_uniform = float(ffr_jax.objective(case, uniform, rtol=1e-10, atol=1e-12))
    share_10 = float(np.mean((x_phys > 0.1) & (x_phys < 0.9)))
    share_05 = float(np.mean((x_phys > 0.05) & (x_phys < 0.95)))
    psi_log = stored["psi"]
    summary = {
        "iterations": int(psi_log.size), "volume": float(np.mean(x_phys)), "psi_optimised": psi_opt,
        "psi_uniform": psi_uniform, "ratio": psi_opt / psi_uniform, "intermediate_0.1_0.9": share_10,
        "intermediate_0.05_0.95": share_05, "wall_time_s": float(sum(sessions)), "sessions": len(sessions),
        "psi_first_iterate": float(psi_log[0]), "psi_last_iterate": float(psi_log[-1]),
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))

    if (args.nx, args.ny, args.modes, args.t1) == (100, 6, 6, 3.0):
        from _results import machine, write_section

        opt = f"--optimizer {args.optimizer}" + (f" --lr {args.lr}" if args.optimizer == "adam" else "")
        command = f"python benchmarks/bench_optimize.py --iters {args.iters} {opt} --rtol {args.rtol}"
        body = "\n".join([
            f"Command: `{command}` (drives `ffr-jax optimize slider-crank`; re-running it resumes the stored run; "
            f"outputs in `{args.out.relative_to(pathlib.Path(__file__).parent.parent)}/`).",
            "",
            f"Reference rod (100 x 6, 588 densities, 6 modes, t1 = 3 s), volume fraction {args.volume}, "
            f"density filter radius {args.filter_radius} elements, adjoint gradients at rtol {args.rtol} / atol 1e-12 "
            "inside the loop; final values re-evaluated at rtol 1e-10 / atol 1e-12.",
            "",
            "| quantity | value |",
            "|---|---:|",
            f"| iterations | {summary['iterations']} |",
            f"| volume of the physical design | {summary['volume']:.6f} |",
            f"| psi, uniform design x = {summary['volume']:.3f} | {psi_uniform:.6e} |",
            f"| psi, optimised design | {psi_opt:.6e} |",
            f"| ratio optimised / uniform | {summary['ratio']:.4f} |",
            f"| share of intermediate densities 0.1 < x < 0.9 | {100 * share_10:.1f} % |",
            f"| share of intermediate densities 0.05 < x < 0.95 | {100 * share_05:.1f} % |",
            f"| wall time of the run ({len(sessions)} session(s), compile included) | {summary['wall_time_s']:.0f} s |",
            "",
            f"Machine: {machine()}. Design: `{args.out.name}/design.png`, convergence: `{args.out.name}/convergence.png`.",
        ])
        write_section("Topology optimisation of the reference rod", body)


if __name__ == "__main__":
    main()
