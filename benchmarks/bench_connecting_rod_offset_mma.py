"""The worked 3-D example's topology optimisation (issue 27): the solid connecting rod of a slider–crank whose crank
pin is offset along the pin axis, so that the rod runs tilted and is loaded across its plane as well.

Scene (`fj.cases.connecting_rod_slider_crank(..., pin_offset=...)`): the rod on the crank pin in a universal joint,
its small end on the slider line in a ball joint; a jerk-free run-up to engine speed (`--speed`, default 100 pi rad/s
= 3000 rpm) in `--ramp` s, modal damping `--zeta` of the rod. Objective: the rod's compliance averaged over the window
`[--average-from, --t1]` (default one whole crank turn at steady speed, after the run-up): the loads of a full turn,
where a run-up's compliance covers part of one. Four modes (`--modes`): with two, the second and third (both in-plane)
cross as the web changes and psi jumps as they swap (RESULTS). MMA with a density filter (radius in metres, isotropic), Heaviside projection
with `fj.beta_continuation` (doubling every `--every` steps up to `--beta-max`), volume fraction `--volume` of the web
(the hubs passive solid).

Writes to `--out` (a folder): `log.csv` and `checkpoint.npz` every step (`fj.optimize`'s; `--resume` continues a
killed run), `step_XXXX.npz` with the physical densities of every step, and `final.npz` (physical densities, element
centroids, histories of psi, volume, grey share, beta and wall time).

    nohup python benchmarks/bench_connecting_rod_offset_mma.py > log 2>&1 &
    python benchmarks/bench_connecting_rod_offset_mma.py --resume --steps 76 --beta-max 256   # RESULTS' tail
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
parser.add_argument("--steps", type=int, default=60)
parser.add_argument("--size", type=float, default=0.012)
parser.add_argument("--layers", type=int, default=2)
parser.add_argument("--modes", type=int, default=4)
parser.add_argument("--pin-offset", type=float, default=0.03)
parser.add_argument("--speed", type=float, default=100 * np.pi)
parser.add_argument("--ramp", type=float, default=0.01)
parser.add_argument("--t1", type=float, default=0.04)
parser.add_argument("--average-from", type=float, default=0.02)
parser.add_argument("--zeta", type=float, default=0.05)
parser.add_argument("--radius", type=float, default=0.025, help="filter radius in metres")
parser.add_argument("--volume", type=float, default=0.5)
parser.add_argument("--move", type=float, default=0.05)
parser.add_argument("--beta-max", type=float, default=64.0)
parser.add_argument("--every", type=int, default=8)
parser.add_argument("--rtol", type=float, default=1e-8)
parser.add_argument("--out", default="benchmarks/results/connecting_rod_offset_mma")
parser.add_argument("--resume", action="store_true")
args = parser.parse_args()

start = time.perf_counter()
case = fj.cases.connecting_rod_slider_crank(args.size, args.layers, args.modes, args.t1, t_ramp=args.ramp,
                                            speed=args.speed, pin_offset=args.pin_offset, damping_ratio=args.zeta,
                                            average_from=args.average_from)
body = case.design_map.body
print(f"{body.mesh.n_elements} H8, {case.n_design} design variables, {body.mesh.n_elements - case.n_design} passive; "
      f"built in {time.perf_counter() - start:.1f} s; load {os.getloadavg()}", flush=True)
filt = fj.DensityFilter(body, args.radius, scale=(1.0, 1.0, 1.0))
projection = fj.HeavisideProjection(eta=0.5, x_min=body.material.x_min)
fun = fj.make_objective(case, method="adjoint", filter=filt, projection=projection, rtol=args.rtol, atol=1e-20)
volume = fj.VolumeConstraint(args.volume, x_min=body.material.x_min, filter=filt, projection=projection)
schedule = fj.beta_continuation(1.0, args.beta_max, every=args.every)
os.makedirs(args.out, exist_ok=True)
centroids = np.asarray(body.domain.design_centroids())
walls = []


def physical(x, k):
    return np.asarray(projection(filt(np.asarray(x)), beta=schedule(k)))


def report(k, x, info):
    walls.append(time.perf_counter() - start)
    x_phys = physical(x, k)
    grey = float(np.mean((x_phys > 0.1) & (x_phys < 0.9)))
    np.savez(os.path.join(args.out, f"step_{k:04d}.npz"), x=np.asarray(x), x_phys=x_phys, beta=schedule(k))
    print(f"step {k}: beta {schedule(k):g}, grey {grey:.3f}, {walls[-1]:.0f} s, load {os.getloadavg()[0]:.1f}",
          flush=True)


result = fj.optimize(fun, case.initial_design(args.volume), fj.MMA(x_min=body.material.x_min, move=args.move), volume,
                     iterations=args.steps, beta=schedule, progress=False, callback=report, directory=args.out,
                     checkpoint_every=1, resume=args.resume)
h = result.history
wall = time.perf_counter() - start
x_phys = physical(result.x, args.steps - 1)
grey = float(np.mean((x_phys > 0.1) & (x_phys < 0.9)))
print(f"psi / psi(uniform start): {h.value[-1] / h.value[0]:.4f} (psi_0 = {h.value[0]:.5e}, last {h.value[-1]:.5e})")
print(f"volume {h.volume[-1]:.4f}, grey share {grey:.4f} (result.grey {result.grey:.4f}), feasible {result.feasible}, "
      f"back-offs {result.back_offs}, {len(h.value)} steps, wall {wall:.0f} s, load {os.getloadavg()}")
print("psi ratio by step:", np.round(np.asarray(h.value) / h.value[0], 4).tolist())
np.savez(os.path.join(args.out, "final.npz"), x=np.asarray(result.x), x_phys=x_phys, centroids=centroids,
         psi=np.asarray(h.value), volume=np.asarray(h.volume), grey=np.asarray(h.grey),
         beta=np.array([schedule(k) for k in range(len(h.value))]), wall=wall, settings=str(vars(args)))
print(f"wrote {args.out}/final.npz")
