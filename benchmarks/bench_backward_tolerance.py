"""The adjoint gradient of the reference case for several backward tolerances: run time and the
relative max-norm difference to autodiff (what the backward tolerance buys).

Usage: `python benchmarks/bench_backward_tolerance.py` (prints a line per tolerance pair).
"""

import time, statistics, jax, numpy as np, equinox as eqx, diffrax
import ffr_jax as fj
case = fj.cases.slider_crank()
x = case.initial_design(0.5)
ref = None
auto = jax.jit(lambda x: fj.value_and_grad(case, x, "autodiff"))
g_auto = np.asarray(auto(x)[1])
for rtol, atol in [(1e-8, 1e-10), (1e-8, 1e-12), (1e-7, 1e-10), (1e-6, 1e-9), (1e-6, 1e-12)]:
    m = fj.Adjoint(rtol=rtol, atol=atol)
    f = jax.jit(lambda x, m=m: fj.value_and_grad(case, x, m))
    c = f.lower(x).compile()
    ts = []
    for _ in range(2):
        t = time.perf_counter(); psi, g = jax.block_until_ready(c(x)); ts.append(time.perf_counter() - t)
    err = np.abs(np.asarray(g) - g_auto).max() / np.abs(g_auto).max()
    print(f"backward rtol {rtol:g} atol {atol:g}: run {min(ts):.2f} s, vs autodiff {err:.1e}", flush=True)
