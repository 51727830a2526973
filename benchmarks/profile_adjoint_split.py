"""Where the adjoint gradient's time goes on the reference case: design map, forward, backward, quadrature (issue 15).

Each stage compiled on its own (`eqx.filter_jit`) and timed after compilation (median of 5):
- `design map`: `case.scene(x)` (FE assembly, modal reduction, body data) and its VJP (one pullback of a
  scene-shaped cotangent, the last step of every design gradient);
- `forward`: the minimal equations of motion with dense output (`solve_minimal`), Rodas5P;
- `backward`: the adjoint ODE on the forward's steps (`Adjoint.backward_solve`), with the number of steps;
- `quadrature`: the gradient integral of paper eq. 44 on those steps.
Then the whole `fj.value_and_grad(case, x, fj.Adjoint(...), solver=fj.Rodas5P())` and one `fj.simulate`
for the ratio the issue asks about.

Usage: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/profile_adjoint_split.py --modes 6 30 --rtol 1e-8`
"""

import argparse
import pathlib
import sys

import equinox as eqx
import jax
import jax.numpy as jnp

import ffr_jax as fj
from ffr_jax._sensitivity._adjoint import _quadrature_on_steps
from ffr_jax._dynamics._simulate import solve_minimal

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _results import timed  # noqa: E402


def split(n_modes, rtol):
    case = fj.cases.slider_crank(n_modes=n_modes)
    x = case.initial_design(0.5)
    atol = rtol * 1e-2
    method = fj.Adjoint(rtol=rtol, atol=atol)
    solver = fj.Rodas5P()
    scene_fn = eqx.filter_jit(case.scene)
    t_scene, scene = timed(scene_fn, x, runs=5)
    pullback = eqx.filter_jit(lambda x, g: eqx.filter_vjp(case.scene, x)[1](g))
    cotangent = jax.tree_util.tree_map(jnp.ones_like, eqx.filter(scene, eqx.is_inexact_array))
    t_vjp, _ = timed(pullback, x, cotangent, runs=5)
    problem = case.problem_for(case.check(x))
    params = (problem.scene, problem.objective)

    @eqx.filter_jit
    def forward(problem):
        return solve_minimal(problem.model, problem.scene, problem.t0, problem.t1, problem.y0, problem.z0,
                             integrand=problem.objective.integrand, solver=solver, rtol=rtol, atol=atol, dense=True,
                             max_steps=200_000)

    @eqx.filter_jit
    def backward(problem, fw):
        return method.backward_solve(problem, fw, solver=solver, max_steps=200_000)[0]

    @eqx.filter_jit
    def quadrature(problem, fw, bw):
        return _quadrature_on_steps(problem, params, fw.solution, bw, method.quadrature, None)

    t_fwd, fw = timed(forward, problem, runs=5)
    t_bwd, bw = timed(backward, problem, fw, runs=5)
    t_quad, _ = timed(quadrature, problem, fw, bw, runs=5)
    whole = eqx.filter_jit(lambda x: fj.value_and_grad(case, x, method, solver=solver, rtol=rtol, atol=atol))
    t_whole, _ = timed(whole, x, runs=3)
    sim = eqx.filter_jit(lambda x: fj.simulate(case, x, solver=solver, rtol=rtol, atol=atol, max_steps=200_000))
    t_sim, _ = timed(sim, x, runs=5)
    steps = int(fw.num_accepted_steps)
    print(f"| {n_modes} | {rtol:g} | {steps} | {t_scene:.3f} | {t_vjp:.3f} | {t_fwd:.3f} | {t_bwd:.3f} | "
          f"{t_quad:.3f} | {t_whole:.3f} | {t_sim:.3f} | {t_whole / t_sim:.2f} | "
          f"{(t_fwd + t_bwd + t_quad) / t_fwd:.2f} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[6, 30])
    parser.add_argument("--rtol", type=float, default=1e-8)
    args = parser.parse_args()
    print("| modes | rtol | steps | design map [s] | its VJP [s] | forward ODE [s] | backward [s] | quadrature [s] | "
          "value_and_grad [s] | simulate [s] | ratio | (forward + backward + quadrature) / forward |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in args.modes:
        split(n, args.rtol)


if __name__ == "__main__":
    main()
