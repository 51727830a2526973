"""Gradients of the worked 3-D example (issue 27): the solid connecting rod in the spatial slider–crank.

`fj.cases.connecting_rod_slider_crank` (gmsh profile, hexahedra, the hubs passive solid, the web designed): the design
gradient of the rod's compliance by the paper's adjoint and by automatic differentiation through the solver, both
pulled back through the design map `p(x)` by one VJP (as `fj.value_and_grad(case, x)` composes them), against
central differences of `psi` on several densities. Too costly for a test: the spatial adjoint and autodiff programs
compile in minutes (benchmarks/RESULTS.md, "Spatial slider–crank"); tests/test_solid_design.py checks the design
chain's derivative (body data) against central differences and the passive regions.

Tolerances of the comparison (printed with the measured numbers):
- adjoint vs autodiff: two discretisations of the same derivative at rtol 1e-10 (forward) / 1e-8 (backward, the
  adjoint's default ratio): 1e-6 of the largest entry.
- central differences, relative step `h = 1e-4` on a density `x_i ~ 0.5`: truncation `~h^2 = 1e-8` relative, solver
  noise `~ rtol |psi| / (h |dpsi/dx_i|)` (1e-6 relative for an entry of the size of `psi`): 1e-4 of the largest entry
  bounds both for the entries compared (the largest, and two of a tenth of it and less).
`atol` is 1e-20: the modal coordinates (~1e-6) and `psi` (~1e-9) are tiny in SI units, so the error control is
relative (rtol) throughout.

    python benchmarks/bench_connecting_rod_gradient.py [--size 0.012] [--layers 2] [--modes 2] [--t1 0.04]
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
from ffr_jax._design.domain import DESIGN  # noqa: E402

RTOL, ATOL = 1e-10, 1e-20
H = 1e-4

parser = argparse.ArgumentParser()
parser.add_argument("--size", type=float, default=0.012)
parser.add_argument("--layers", type=int, default=2)
parser.add_argument("--modes", type=int, default=2)
parser.add_argument("--t1", type=float, default=0.04)
parser.add_argument("--t-ramp", type=float, default=0.02)
args = parser.parse_args()

t = time.perf_counter()
case = fj.cases.connecting_rod_slider_crank(args.size, args.layers, args.modes, args.t1, t_ramp=args.t_ramp)
body = case.design_map.body
print(f"case built in {time.perf_counter() - t:.1f} s: {body.mesh.n_elements} H8, {body.mesh.n_dof} dof, "
      f"{case.n_design} design variables, {body.mesh.n_elements - case.n_design} passive (hubs)", flush=True)
print("frequencies [Hz] at x = 0.5:", np.asarray(body.frequencies(case.initial_design(0.5))))
x = case.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(case.n_design, dtype=float))

t = time.perf_counter()
scene, pullback = eqx.filter_vjp(case.scene, x)
problem = case.problem.with_scene(scene)
print(f"design map p(x) and its VJP closure: {time.perf_counter() - t:.1f} s", flush=True)

results = {}
for method in ("adjoint", "autodiff"):
    t = time.perf_counter()
    psi, grad = fj.value_and_grad(problem, method=method, rtol=RTOL, atol=ATOL)
    (g,) = pullback(grad.scene)
    results[method] = (float(psi), np.asarray(g))
    print(f"{method}: compile + run {time.perf_counter() - t:.1f} s, psi = {float(psi):.10e}", flush=True)

g_adj, g_ad = results["adjoint"][1], results["autodiff"][1]
scale = np.max(np.abs(g_ad))
print(f"adjoint vs autodiff: max |difference| / max |g| = {np.max(np.abs(g_adj - g_ad)) / scale:.1e} (bound 1e-6)")
order = np.argsort(-np.abs(g_adj))
entries = [int(order[0]), int(order[len(order) // 10]), int(order[len(order) // 2])]
t = time.perf_counter()
for i in entries:
    e = jnp.zeros(case.n_design).at[i].set(H)
    fd = (float(fj.objective(case.problem_for(x + e), rtol=RTOL, atol=ATOL))
          - float(fj.objective(case.problem_for(x - e), rtol=RTOL, atol=ATOL))) / (2 * H)
    print(f"entry {i}: adjoint {g_adj[i]:.10e}, autodiff {g_ad[i]:.10e}, central differences {fd:.10e}; "
          f"|adjoint - fd| / max|g| = {abs(g_adj[i] - fd) / scale:.1e} (bound 1e-4)", flush=True)
print(f"central differences (6 objectives, first compiles): {time.perf_counter() - t:.1f} s")
groups_web = int(np.count_nonzero(np.asarray(body.domain.roles) == DESIGN))
print(f"passive: {body.mesh.n_elements - case.n_design} hub elements carry no design variable "
      f"(n_design = {case.n_design} = design-role elements {groups_web})")
