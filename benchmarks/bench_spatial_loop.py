"""The spatial four-bar (RSSR, `fj.cases.spatial_four_bar`, issue 26): energy drift and joint closure of the free
linkage under gravity over `--t1` seconds, at several tolerances. Prints one markdown table.

    python benchmarks/bench_spatial_loop.py [--t1 10] [--rtols 1e-8 1e-10]
"""

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj


@eqx.filter_jit
def energy_and_closure(problem, positions, velocities):
    scene = problem.scene

    def one(y, z):
        return (scene.kinetic_energy(y, z) + scene.potential_energy(jnp.zeros(()), y),
                jnp.max(jnp.abs(scene.constraint_residual(jnp.zeros(()), y))))

    return jax.vmap(one)(positions, velocities)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--t1", type=float, default=10.0)
    parser.add_argument("--rtols", type=float, nargs="+", default=[1e-8, 1e-10])
    args = parser.parse_args()
    start = time.perf_counter()
    problem = fj.cases.spatial_four_bar(args.t1)
    build = time.perf_counter() - start
    ts = jnp.linspace(0.0, args.t1, 1001)
    rows = []
    for rtol in args.rtols:
        start = time.perf_counter()
        traj = jax.block_until_ready(fj.simulate(problem, ts=ts, rtol=rtol, atol=rtol / 100))
        first = time.perf_counter() - start
        start = time.perf_counter()
        jax.block_until_ready(fj.simulate(problem, ts=ts, rtol=rtol, atol=rtol / 100))
        run = time.perf_counter() - start
        energy, closure = (np.asarray(a) for a in energy_and_closure(problem, traj.positions, traj.velocities))
        p = np.asarray(traj.positions)[:, 3:7]
        turns = np.ptp(np.unwrap(2.0 * np.arctan2(p[:, 3], p[:, 0]))) / (2 * np.pi)
        rows.append(f"| {rtol:g} | {np.ptp(energy) / np.max(np.abs(energy)):.1e} | {np.max(closure):.1e} | {turns:.2f} | "
                    f"{int(traj.num_steps)} | {first:.1f} | {run:.2f} |")
    print(f"t1 = {args.t1} s, Dopri8, atol = rtol / 100; problem built (partition, assembly, compiles) in {build:.1f} s\n")
    print("| rtol | energy drift (max - min) / max abs(E) | max joint residual [m] | crank turns | steps | first call [s] | run [s] |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
