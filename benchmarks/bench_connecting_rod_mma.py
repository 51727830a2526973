"""A short MMA topology optimisation of the worked 3-D example (issue 27): the solid connecting rod's web in the spatial
slider–crank, compliance of the rod over the run-up, density filter (radius in metres), Heaviside projection with a
fast continuation, volume fraction 0.5 of the web (the hubs passive solid).

A demonstration of the chain at a tiny size (the coarse gmsh rod, one layer, two modes, a short motion), not a
converged design: it prints psi of each step relative to the uniform start, the volume and the grey share
(`0.1 < x_phys < 0.9`) and the wall time, and writes the final physical densities to `--out` (.npz, with the
element centroids) for a picture.

    python benchmarks/bench_connecting_rod_mma.py [--steps 12] [--size 0.016] [--out benchmarks/results/...npz]
"""

import argparse
import os
import time

os.environ["XLA_FLAGS"] = ("--xla_cpu_enable_concurrency_optimized_scheduler=false --xla_cpu_multi_thread_eigen=false "
                           "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0 "
                           "--xla_llvm_disable_expensive_passes=true")
os.environ.setdefault("FFR_JAX_NO_CACHE", "1")

import numpy as np  # noqa: E402

import ffr_jax as fj  # noqa: E402

parser = argparse.ArgumentParser()
parser.add_argument("--steps", type=int, default=12)
parser.add_argument("--size", type=float, default=0.016)
parser.add_argument("--layers", type=int, default=1)
parser.add_argument("--modes", type=int, default=2)
parser.add_argument("--t1", type=float, default=0.04)
parser.add_argument("--radius", type=float, default=0.02, help="filter radius in metres")
parser.add_argument("--volume", type=float, default=0.5)
parser.add_argument("--move", type=float, default=None, help="MMA move limit (default: MMA's own)")
parser.add_argument("--out", default="benchmarks/results/connecting_rod_mma.npz")
args = parser.parse_args()

start = time.perf_counter()
case = fj.cases.connecting_rod_slider_crank(args.size, args.layers, args.modes, args.t1, t_ramp=args.t1 / 2)
body = case.design_map.body
print(f"{body.mesh.n_elements} H8, {case.n_design} design variables, {body.mesh.n_elements - case.n_design} passive; "
      f"built in {time.perf_counter() - start:.1f} s", flush=True)
filt = fj.DensityFilter(body, args.radius, scale=(1.0, 1.0, 1.0))
projection = fj.HeavisideProjection(eta=0.5, x_min=body.material.x_min)
fun = fj.make_objective(case, method="adjoint", filter=filt, projection=projection, rtol=1e-8, atol=1e-20)
volume = fj.VolumeConstraint(args.volume, x_min=body.material.x_min, filter=filt, projection=projection)
schedule = fj.beta_continuation(1.0, 16.0, every=max(1, args.steps // 5))


def report(k, x, info):
    print(f"step {k}: {time.perf_counter() - start:.0f} s", flush=True)


result = fj.optimize(fun, case.initial_design(args.volume), fj.MMA(x_min=body.material.x_min, **({} if args.move is None else {'move': args.move})), volume,
                     iterations=args.steps, beta=schedule, progress=False, callback=report)
h = result.history
print(f"psi / psi(uniform start): {h.value[-1] / h.value[0]:.3f} (psi_0 = {h.value[0]:.4e}, last {h.value[-1]:.4e})")
print(f"volume {h.volume[-1]:.4f}, grey share {result.grey:.3f}, feasible {result.feasible}, back-offs "
      f"{result.back_offs}, {len(h.value)} steps, wall {time.perf_counter() - start:.0f} s")
print("psi ratio by step:", np.round(h.value / h.value[0], 4).tolist())
x_phys = np.asarray(projection(filt(result.x), beta=schedule(args.steps - 1)))
os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
np.savez(args.out, x_phys=x_phys, centroids=body.domain.design_centroids(), psi=h.value, volume=h.volume,
         grey=h.grey)
print(f"wrote {args.out}")
