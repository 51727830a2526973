"""Volume and first-frequency constraints together (MMA) on a reduced rod, and constraint sets no design meets.

1. `ffr-jax optimize slider-crank --optimizer mma --frequency-min F` on the reduced case of the strategy
   table (50 x 6, t1 = 1 s, autodiff gradients at rtol 1e-8, filter 1.5, projection beta 1 -> 32 x2 every
   15 steps), checkpointed (re-running resumes). F = 70 Hz lies above f_1 = 66.1 Hz of the *solid* rod:
   the compliance-optimal designs of the strategy table have f_1 = 64 Hz, so the bound is active, and it
   is reachable at half the volume (a sandwich of the outer rows with webs every 6 columns: 73.6 Hz at
   V = 0.45). At the end: every constraint's value at the final design, psi of the design and of the
   uniform design of equal volume (rtol 1e-10), f_1 and f_2, the grey share; the design, its convergence
   plot, the animation (GIF), the VTU and the SVG/DXF outline go to the output directory.
2. Bad input, each with the message a user sees: a mass bound below the lightest design and a frequency
   bound above the Rayleigh-quotient bound (refused at construction); a volume bound with a lower mass
   bound that contradicts it, and a frequency bound 1.5 x the solid rod's (reported infeasible at the end
   of an MMA run on the mass).

Usage: `python benchmarks/bench_constrained.py [--iters 100 --frequency-min 70 --out DIR]`. Writes the
RESULTS.md section "Volume and first-frequency constraints (MMA)" (default settings only).
"""

import argparse
import json
import pathlib
import time
import warnings

import jax
import numpy as np

import ffr_jax as fj
from ffr_jax._app._cli import main as cli


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=100)
    parser.add_argument("--frequency-min", type=float, default=70.0)
    parser.add_argument("--volume", type=float, default=0.5)
    parser.add_argument("--nx", type=int, default=50)
    parser.add_argument("--t1", type=float, default=1.0)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--out", type=pathlib.Path,
                        default=pathlib.Path(__file__).parent / "results" / "constrained" / "mma_volume_frequency")
    args = parser.parse_args()
    settings = ["--volume", str(args.volume), "--optimizer", "mma", "--mma-move", "0.2", "--frequency-min",
                str(args.frequency_min), "--method", "autodiff", "--rtol", "1e-08", "--nx", str(args.nx), "--ny", "6",
                "--modes", "6", "--t1", str(args.t1), "--projection-beta", "1", "--beta-max", "32",
                "--beta-every", "15"]
    resume = (args.out / "checkpoint.npz").exists()
    start = time.perf_counter()
    code = cli(["optimize", "slider-crank", "--iters", str(args.iters), "--no-progress", "--checkpoint-every", "10"]
               + (["--resume", str(args.out)] if resume else ["--out", str(args.out)]) + settings)
    wall = time.perf_counter() - start
    if code != 0:
        raise SystemExit(code)
    timing = args.out / "wall_time.json"
    if not resume or not timing.exists():
        timing.write_text(json.dumps(wall))
    wall = json.loads(timing.read_text())

    stored = np.load(args.out / "design.npz")
    x_phys = stored["x_phys"]
    case = fj.cases.slider_crank(args.nx, 6, 6, args.t1)
    uniform = case.initial_design(float(np.mean(x_phys)))
    psi_opt = float(fj.objective(case, x_phys, rtol=1e-10, atol=1e-12))
    psi_uniform = float(fj.objective(case, uniform, rtol=1e-10, atol=1e-12))
    frequencies = jax.jit(lambda x: case.frequencies(x))
    f_opt, f_uniform, f_solid = (np.asarray(frequencies(x)) for x in (x_phys, uniform, case.initial_design(1.0)))
    names = json.loads(str(stored["constraint_names"]))
    # The descriptions of the constraints at the final design (physical densities: no filter here).
    final = [fj.VolumeConstraint(args.volume, x_min=case.material.x_min).describe(float(np.mean(x_phys)) / args.volume - 1),
             fj.FrequencyConstraint(case, args.frequency_min).describe(1 - float(f_opt[0]) / args.frequency_min)]
    animation = fj.animate(case, x_phys, args.out / "animation.gif", frames=args.frames,
                           title=f"MMA, V <= {args.volume}, f_1 >= {args.frequency_min:g} Hz")
    fj.write_vtu(args.out / "design.vtu", case, x_phys)
    fj.write_svg(args.out / "outline.svg", case, x_phys)
    fj.write_dxf(args.out / "outline.dxf", case, x_phys)
    summary = {
        "iterations": int(stored["psi"].size), "constraint_names": names,
        "constraints_final": stored["constraints"].tolist(), "final": final,
        "volume": float(np.mean(x_phys)), "psi_optimised": psi_opt, "psi_uniform": psi_uniform,
        "ratio": psi_opt / psi_uniform, "f_optimised": f_opt[:2].tolist(), "f_uniform": f_uniform[:2].tolist(),
        "f_solid": f_solid[:2].tolist(), "grey_0.1_0.9": float(np.mean((x_phys > 0.1) & (x_phys < 0.9))),
        "wall_time_s": wall, "animation": {"frames": animation.frames, "amplification": animation.amplification,
                                           "largest_mm": 1e3 * animation.max_displacement},
    }
    bad = bad_input(case)
    summary["bad_input"] = bad
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    if (args.iters, args.frequency_min, args.nx, args.t1) == (100, 70.0, 50, 1.0):
        from _results import machine, write_section

        write_section("Volume and first-frequency constraints (MMA)", section(args, summary, machine()))


def bad_input(case):
    """The messages of four constraint sets that no design meets."""
    out = {}
    lightest, heaviest = fj.MassConstraint(case.design, 1.0).range
    for key, make in (("mass below the lightest design", lambda: fj.MassConstraint(case.design, 0.5 * lightest)),
                      ("frequency above the Rayleigh bound", lambda: fj.FrequencyConstraint(case, 1e4))):
        try:
            make()
            out[key] = "not refused"
        except ValueError as err:
            out[key] = f"ValueError at construction: {err}"
    mass = fj.MassConstraint(case.design, heaviest)  # the objective of these runs: the mass itself
    solid = fj.FrequencyConstraint(case, 1.0).solid
    mass_06 = float(mass.mass(case.design.initial_design(0.6)))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sets = {
            "volume <= 0.3 with mass >= mass(x = 0.6)": (fj.VolumeConstraint(0.3),
                                                        fj.MassConstraint(case.design, mass_06, lower=True)),
            f"f_1 >= 1.5 x solid ({1.5 * solid:.1f} Hz), volume <= 0.5": (fj.VolumeConstraint(0.5),
                                                                          fj.FrequencyConstraint(case, 1.5 * solid)),
        }
    construction = [str(w.message) for w in caught]
    for key, constraints in sets.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = fj.optimize(lambda x: mass.value_and_grad(x), case.initial_design(0.5), fj.MMA(case.material.x_min),
                                 constraints, iterations=40, progress=False)
        messages = [str(w.message) for w in caught if issubclass(w.category, fj.ConstraintViolationWarning)]
        out[key] = {"feasible": result.feasible, "final": list(result.descriptions),
                    "warning": messages[0] if messages else None,
                    "finite": bool(np.all(np.isfinite(result.history.constraint_values)))}
    out["warnings at construction"] = construction
    return out


def section(args, s, machine_line):
    lines = [
        "Command: `python benchmarks/bench_constrained.py` (drives `ffr-jax optimize slider-crank --optimizer mma "
        f"--frequency-min {args.frequency_min:g} --volume {args.volume} --method autodiff --rtol 1e-08 --nx {args.nx} "
        f"--ny 6 --modes 6 --t1 {args.t1} --projection-beta 1 --beta-max 32 --beta-every 15 --mma-move 0.2`; "
        "re-running resumes the stored run).",
        "",
        f"Reduced rod ({args.nx} x 6, 6 modes, t1 = {args.t1} s), MMA with two inequality constraints: volume "
        f"`mean(x_phys) <= {args.volume}` and first natural frequency `f_1 >= {args.frequency_min:g} Hz`. The bound lies "
        f"above the solid rod's f_1 = {s['f_solid'][0]:.1f} Hz (the compliance-optimal designs of the strategy table "
        "have 64 Hz): removing mass near the neutral axis while keeping webs raises f_1 above the solid rod's.",
        "",
        "| quantity | value |",
        "|---|---:|",
        f"| iterations | {s['iterations']} |",
        *[f"| constraint at the final design | {line} |" for line in s["final"]],
        f"| f_1, f_2 optimised / uniform / solid [Hz] | {s['f_optimised'][0]:.2f}, {s['f_optimised'][1]:.1f} / "
        f"{s['f_uniform'][0]:.2f}, {s['f_uniform'][1]:.1f} / {s['f_solid'][0]:.2f}, {s['f_solid'][1]:.1f} |",
        f"| psi, uniform design x = {s['volume']:.3f} | {s['psi_uniform']:.6e} |",
        f"| psi, optimised physical design | {s['psi_optimised']:.6e} |",
        f"| **ratio optimised / uniform** | **{s['ratio']:.4f}** |",
        f"| share of intermediate densities 0.1 < x_phys < 0.9 | {100 * s['grey_0.1_0.9']:.1f} % |",
        f"| wall time of the run (compile included) | {s['wall_time_s']:.0f} s |",
        "",
        f"Files in `results/constrained/{args.out.name}/`: `design.png`, `convergence.png` (psi and both constraints), "
        f"`animation.gif` ({s['animation']['frames']} frames, elastic displacement x {s['animation']['amplification']:g}, "
        f"largest {s['animation']['largest_mm']:.3g} mm), `design.vtu` (density, mode shapes), `outline.svg`, "
        "`outline.dxf`.",
        "",
        "![animation](results/constrained/mma_volume_frequency/animation.gif)",
        "",
        "Constraint sets that no design meets (same rod; the objective of the MMA runs is the mass, 40 steps):",
        "",
        "| constraint set | outcome |",
        "|---|---|",
    ]
    for key, value in s["bad_input"].items():
        if key == "warnings at construction":
            continue
        if isinstance(value, str):
            lines.append(f"| {key} | {value} |")
        else:
            lines.append(f"| {key} | feasible: {value['feasible']}; finite history: {value['finite']}; "
                         f"ConstraintViolationWarning: {value['warning']} |")
    for message in s["bad_input"]["warnings at construction"]:
        lines.append(f"| (warning at construction) | {message} |")
    lines += ["", f"Machine: {machine_line}."]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
