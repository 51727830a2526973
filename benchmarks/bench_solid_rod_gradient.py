"""The one-layer H8 rod (Poisson's ratio 0) in the spatial slider-crank against the planar Q4 case (issue 27):
psi and the design gradient by the paper's adjoint (rtol 1e-10 / atol 1e-12), on `slider_crank(4, 2, 2, 0.1)`.

Too costly for a test (the spatial adjoint compiles in minutes; tests/test_solid_rod.py checks psi, the body data and
their design tangents). The solid's design gradient is the adjoint's scene gradient pulled back through `p(x)` by one
VJP, as `fj.value_and_grad(case, x)` does. The suite's XLA flags (tests/conftest.py) for a comparable compile time.

    python benchmarks/bench_solid_rod_gradient.py            # 2 in-plane modes, 1 out-of-plane mode
    N_OUT=0 python benchmarks/bench_solid_rod_gradient.py    # in-plane modes only
"""

import os
import time

os.environ["XLA_FLAGS"] = ("--xla_cpu_enable_concurrency_optimized_scheduler=false --xla_cpu_multi_thread_eigen=false "
                           "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0 "
                           "--xla_llvm_disable_expensive_passes=true")
os.environ.setdefault("FFR_JAX_NO_CACHE", "1")

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import ffr_jax as fj  # noqa: E402

NX, NY, NQ = 4, 2, 2
n_out = int(os.environ.get("N_OUT", "1"))
solid = fj.cases.solid_slider_crank(NX, NY, NQ, 0.1, poisson=0.0, out_of_plane_modes=n_out)
planar = fj.cases.slider_crank(NX, NY, NQ, 0.1, rod=fj.cases.rod_body(NX, NY, NQ, poisson=0.0))
x = 0.5 + 0.2 * jnp.sin(1.7 * jnp.arange(planar.n_design, dtype=float))
t = time.perf_counter()
psi_p, g_p = fj.value_and_grad(planar, x, method="adjoint", rtol=1e-10, atol=1e-12)
print(f"planar adjoint, compile + run: {time.perf_counter() - t:.1f} s", flush=True)
t = time.perf_counter()
scene, pullback = eqx.filter_vjp(eqx.filter_jit(solid.scene), x)
psi_s, grad = fj.value_and_grad(solid.problem.with_scene(scene), method="adjoint", rtol=1e-10, atol=1e-12)
(g_s,) = pullback(grad.scene)
print(f"solid ({NQ} in-plane + {n_out} out-of-plane modes) adjoint, compile + run: {time.perf_counter() - t:.1f} s")
print(f"psi: solid {float(psi_s):.16e}, planar {float(psi_p):.16e}, relative difference "
      f"{abs(float(psi_s - psi_p)) / abs(float(psi_p)):.1e}")
print(f"design gradient: max |g_solid - g_planar| / max |g_planar| = "
      f"{float(jnp.max(jnp.abs(g_s - g_p)) / jnp.max(jnp.abs(g_p))):.1e}")
