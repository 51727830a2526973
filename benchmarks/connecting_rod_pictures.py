"""Pictures of the worked 3-D example's design (issue 27): the surface of `x_phys >= 0.5` from two views (PNG) and
a VTU series of the motion for ParaView (density, elastic displacement, the rod's placement over time).

Reads the optimisation's result (`final.npz`, or with `--step K` the densities of step K) from the folder of
`bench_connecting_rod_offset_mma.py` and rebuilds its case from the settings stored there.

    python benchmarks/connecting_rod_pictures.py [--run benchmarks/results/connecting_rod_offset_mma] [--frames 41]
"""

import argparse
import ast
import os
import time

os.environ["XLA_FLAGS"] = ("--xla_cpu_enable_concurrency_optimized_scheduler=false --xla_cpu_multi_thread_eigen=false "
                           "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0 "
                           "--xla_llvm_disable_expensive_passes=true")
os.environ.setdefault("FFR_JAX_NO_CACHE", "1")

import numpy as np  # noqa: E402

import ffr_jax as fj  # noqa: E402

parser = argparse.ArgumentParser()
parser.add_argument("--run", default="benchmarks/results/connecting_rod_offset_mma")
parser.add_argument("--step", type=int, default=None, help="draw this step's densities instead of final.npz")
parser.add_argument("--frames", type=int, default=41)
parser.add_argument("--no-vtu", action="store_true")
args = parser.parse_args()

final = np.load(os.path.join(args.run, "final.npz")) if args.step is None else None
source = final if final is not None else np.load(os.path.join(args.run, f"step_{args.step:04d}.npz"))
x_phys = np.asarray(source["x_phys"])
settings = ast.literal_eval(str(final["settings"])) if final is not None else {}
s = {"size": 0.012, "layers": 2, "modes": 2, "t1": 0.04, "ramp": 0.01, "speed": 100 * np.pi, "pin_offset": 0.03,
     "zeta": 0.05, "average_from": 0.02, **settings}
start = time.perf_counter()
case = fj.cases.connecting_rod_slider_crank(s["size"], s["layers"], s["modes"], s["t1"], t_ramp=s["ramp"],
                                            speed=s["speed"], pin_offset=s["pin_offset"], damping_ratio=s["zeta"],
                                            average_from=s["average_from"])
grey = float(np.mean((x_phys > 0.1) & (x_phys < 0.9)))
label = "final" if args.step is None else f"step {args.step}"
title = (f"connecting rod, {label}: surface of x_phys >= 0.5 (hubs grey), volume {x_phys.mean():.3f}, "
         f"grey {100 * grey:.1f} %")
for k, view in enumerate(((30.0, -70.0), (-30.0, 110.0))):
    path = os.path.join(args.run, f"design_view{k + 1}.png")
    fj.plot_solid_design(case.design, x_phys, path, views=(view,), title=title)
    print(f"wrote {path}")
fj.plot_solid_design(case.design, x_phys, os.path.join(args.run, "design.png"), title=title)
if not args.no_vtu:
    pvd = fj.write_vtu_series(os.path.join(args.run, "connecting_rod.pvd"), case, x_phys, frames=args.frames)
    print(f"wrote {pvd} ({args.frames} frames) in {time.perf_counter() - start:.0f} s")
