"""Gradient check of the worked 3-D example's design objective (issue 27): the connecting rod on the offset crank pin
(universal joint, ball joint on the slider line, modal damping), the compliance averaged over a window of the motion
(`fj.TimeWindow`): the adjoint gradient, pulled back through `p(x)` by one VJP, against central differences of psi
on three entries (largest, 10th percentile, median). The windowed integrand jumps at the window's start, which the
problem's `jump_ts` hands to the step-size controller.

    python benchmarks/bench_connecting_rod_offset_gradient.py [--size 0.016 --layers 1 --t1 0.02]
"""

import argparse
import os
import time

os.environ["XLA_FLAGS"] = ("--xla_cpu_enable_concurrency_optimized_scheduler=false --xla_cpu_multi_thread_eigen=false "
                           "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0 "
                           "--xla_llvm_disable_expensive_passes=true")
os.environ.setdefault("FFR_JAX_NO_CACHE", "1")

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import ffr_jax as fj  # noqa: E402

RTOL, ATOL = 1e-10, 1e-20
H = 1e-4

parser = argparse.ArgumentParser()
parser.add_argument("--size", type=float, default=0.016)
parser.add_argument("--layers", type=int, default=1)
parser.add_argument("--modes", type=int, default=2)
parser.add_argument("--t1", type=float, default=0.02)
parser.add_argument("--autodiff", action="store_true", help="also jax.grad through the solver (every entry)")
args = parser.parse_args()

t = time.perf_counter()
case = fj.cases.connecting_rod_slider_crank(args.size, args.layers, args.modes, args.t1, t_ramp=args.t1 / 4,
                                            speed=100 * np.pi, pin_offset=0.03, damping_ratio=0.05,
                                            average_from=args.t1 / 2)
body = case.design_map.body
print(f"case built in {time.perf_counter() - t:.1f} s: {body.mesh.n_elements} H8, {case.n_design} design variables; "
      f"load {os.getloadavg()}", flush=True)
x = case.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(case.n_design, dtype=float))
t = time.perf_counter()
scene, pullback = eqx.filter_vjp(case.scene, x)
problem = case.problem.with_scene(scene)
psi, grad = fj.value_and_grad(problem, method="adjoint", rtol=RTOL, atol=ATOL)
(g,) = pullback(grad.scene)
g = np.asarray(g)
print(f"adjoint: compile + run {time.perf_counter() - t:.1f} s, psi = {float(psi):.10e}", flush=True)
scale = np.max(np.abs(g))
order = np.argsort(-np.abs(g))
if args.autodiff:
    t = time.perf_counter()
    psi_ad, grad_ad = fj.value_and_grad(problem, method="autodiff", rtol=RTOL, atol=ATOL)
    (g_ad,) = pullback(grad_ad.scene)
    g_ad = np.asarray(g_ad)
    print(f"autodiff: compile + run {time.perf_counter() - t:.1f} s, psi = {float(psi_ad):.10e}; over all "
          f"{g.size} entries max |adjoint - autodiff| / max|g| = {np.max(np.abs(g - g_ad)) / scale:.1e} (bound 1e-6: "
          "two discretisations of one derivative at the solver tolerance); largest entry adjoint "
          f"{g[order[0]]:.10e}, autodiff {g_ad[order[0]]:.10e}", flush=True)
t = time.perf_counter()
for i in (int(order[0]), int(order[len(order) // 10]), int(order[len(order) // 2])):
    e = jnp.zeros(case.n_design).at[i].set(H)
    fd = (float(fj.objective(case.problem_for(x + e), rtol=RTOL, atol=ATOL))
          - float(fj.objective(case.problem_for(x - e), rtol=RTOL, atol=ATOL))) / (2 * H)
    print(f"entry {i}: adjoint {g[i]:.10e}, central differences {fd:.10e}; |adjoint - fd| / max|g| = "
          f"{abs(g[i] - fd) / scale:.1e} (bound 1e-4)", flush=True)
print(f"central differences (6 objectives, one compile): {time.perf_counter() - t:.1f} s; load {os.getloadavg()}")
