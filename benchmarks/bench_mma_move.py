"""MMA's move limit on a small slider-crank: psi and volume over the first steps, with and without a filter.

The case is the test family's (REFERENCE_CASE §5: 12 x 2 rod, 4 modes, t1 = 0.15 s, t_ramp = 0.05 s), the
objective the adjoint gradient at rtol 1e-6 / atol 1e-12, the volume an upper bound V <= 0.5 (MMA), the start
the uniform 0.5. For each filter (none; the README's cone of 1.5 elements) and move limit, `--iters` steps of
`fj.optimize`: psi_k / psi_0 per step, the largest and the last, the volume at the end, and the run time after
the objective's compilation (one compile per filter, shared by the move limits). Writes
benchmarks/results/mma_move.md.

    python benchmarks/bench_mma_move.py [--iters 8] [--moves 0.05 0.1 0.2 0.5]
"""

import argparse
import pathlib
import time

import numpy as np

import ffr_jax as fj


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iters", type=int, default=8)
    parser.add_argument("--moves", type=float, nargs="+", default=[0.05, 0.1, 0.2, 0.5])
    args = parser.parse_args()
    case = fj.cases.slider_crank(nx=12, ny=2, n_modes=4, t1=0.15, t_ramp=0.05)
    lines = [f"`fj.optimize` with `fj.MMA(x_min, move=...)`, V <= 0.5 from the uniform 0.5, {args.iters} steps, "
             "12 x 2 family rod (4 modes, t1 = 0.15 s), adjoint at rtol 1e-6.", "",
             "| filter | move | psi_k / psi_0 per step | largest | last | volume at the end | run [s] |",
             "|---|---:|---|---:|---:|---:|---:|"]
    for radius in (None, 1.5):
        filt = None if radius is None else fj.DensityFilter(case.design, radius=radius)
        fun = fj.make_objective(case, "adjoint", filter=filt, rtol=1e-6, atol=1e-12)
        volume = fj.VolumeConstraint(0.5, x_min=case.material.x_min, filter=filt)
        fj.optimize(fun, case.initial_design(0.5), fj.MMA(case.material.x_min), volume, iterations=1,
                    progress=False)  # compiles the objective, shared by the runs below
        for move in args.moves:
            start = time.perf_counter()
            result = fj.optimize(fun, case.initial_design(0.5), fj.MMA(case.material.x_min, move=move), volume,
                                 iterations=args.iters, progress=False)
            seconds = time.perf_counter() - start
            ratio = result.history.value / result.history.value[0]
            x_phys = np.asarray(fj.physical_densities(result.x, filt, None))
            row = (f"| {'none' if radius is None else f'cone {radius} elements'} | {move:g} | "
                   f"{' '.join(f'{r:.3f}' for r in ratio)} | {ratio.max():.3f} | {ratio[-1]:.3f} | "
                   f"{x_phys.mean():.4f} | {seconds:.1f} |")
            print(row, flush=True)
            lines.append(row)
    out = pathlib.Path(__file__).parent / "results" / "mma_move.md"
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
