"""The heavy symmetric top (issue 26): steady precession against the analytic rate, and the drift of the
energy and of the two conserved angular momenta (about the vertical and about the symmetry axis).

A disc of mass m and radius r on a massless stem, centre of mass at l on the symmetry axis (body z) from
the tip, which sits in a frictionless ground socket (a spherical joint). Started on the slow steady
precession of tilt theta and axial spin omega3 (Omega from `I1 Omega^2 cos theta - I3 omega3 Omega + m g l = 0`),
and released with spin only (a nutating top). Prints one markdown table; times are medians of `--runs`
solves after a compiling one.

    python benchmarks/bench_spatial_top.py [--t1 3] [--runs 3]
"""

import argparse
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj
from ffr_jax._spatial import _rigid_body
from ffr_jax._spatial._euler_parameters import rotation_matrix

M, R, L, G = 1.0, 0.1, 0.1, 9.81
I3, I1 = 0.5 * M * R**2, 0.25 * M * R**2 + M * L**2


def precession_rate(spin, tilt):
    b = I3 * spin
    return 2.0 * M * G * L / (b + np.sqrt(b * b - 4.0 * I1 * M * G * L * np.cos(tilt)))


def problem(tilt, body_omega, t1):
    data = fj.spatial_rigid_body_data(M, [0.0, 0.0, M * L], np.diag([I1, I1, I3]), [[0.0, 0.0, 0.0]])
    scene = fj.Scene(bodies=(fj.Body("top", data),), constraints=(fj.SphericalJoint(0, 0),),
                     forces=(fj.Gravity((0.0, 0.0, -G)),))
    p0 = fj.euler_parameters((1.0, 0.0, 0.0), tilt)
    rates = np.asarray(fj.euler_parameter_rates(p0, body_omega))
    return fj.Problem(scene, t1, positions=np.concatenate([np.zeros(3), p0]), velocities=rates,
                      objective=fj.KineticEnergy())


@eqx.filter_jit
def invariants(problem, positions, velocities):
    scene = problem.scene
    data = scene.bodies[0].data

    def one(y, z):
        axis = rotation_matrix(y[3:7])[:, 2]
        _, h = _rigid_body.momenta(data, y, z)
        return axis, scene.kinetic_energy(y, z) + scene.potential_energy(jnp.zeros(()), y), h[2], h @ axis, y[3:7] @ y[3:7]

    return jax.vmap(one)(positions, velocities)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--t1", type=float, default=3.0)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--rtol", type=float, default=1e-10)
    args = parser.parse_args()
    ts = jnp.linspace(0.0, args.t1, 301)
    rows = []
    for tilt, spin in ((0.5, 60.0), (1.2, 100.0), (np.pi / 2, 60.0)):
        omega = precession_rate(spin, tilt)
        for start, body_omega in (("steady", [0.0, omega * np.sin(tilt), spin]), ("spin only", [0.0, 0.0, spin])):
            prob = problem(tilt, body_omega, args.t1)
            run = lambda: fj.simulate(prob, ts=ts, rtol=args.rtol, atol=args.rtol / 100)
            start_time = time.perf_counter()
            traj = jax.block_until_ready(run())
            first = time.perf_counter() - start_time
            times = []
            for _ in range(args.runs):
                start_time = time.perf_counter()
                jax.block_until_ready(run())
                times.append(time.perf_counter() - start_time)
            axis, energy, h_z, h_3, norm2 = (np.asarray(a) for a in invariants(prob, traj.positions, traj.velocities))
            t = np.asarray(traj.ts)
            azimuth = np.unwrap(np.arctan2(axis[:, 0], -axis[:, 1]))
            tilt_t = np.arccos(np.clip(axis[:, 2], -1.0, 1.0))
            if start == "steady":
                rate = np.polyfit(t, azimuth - azimuth[0], 1)[0]
                rate_error = f"{abs(rate - omega) / omega:.1e}"
                angle_error = f"{np.max(np.abs(azimuth - azimuth[0] - omega * t)):.1e}"
            else:
                rate_error = angle_error = "-"
            rows.append(
                f"| {tilt:.3f} | {spin:g} | {start} | {omega:.6f} | {rate_error} | {angle_error} | {np.ptp(tilt_t):.1e} | "
                f"{np.ptp(energy) / abs(energy[0]):.1e} | {np.ptp(h_z) / (I3 * spin):.1e} | {np.ptp(h_3) / (I3 * spin):.1e} | "
                f"{np.max(np.abs(norm2 - 1)):.1e} | {int(traj.num_steps)} | {first:.2f} | {np.median(times):.3f} |"
            )
    print(f"t1 = {args.t1} s, rtol {args.rtol:g}, atol {args.rtol / 100:g}, Dopri8; {fj.__name__} on {jax.default_backend()}\n")
    print("| tilt [rad] | omega3 [rad/s] | start | Omega analytic [rad/s] | rate error (rel.) | phi - Omega t (max) [rad] | "
          "tilt range [rad] | energy drift (rel.) | H_vertical drift / (I3 omega3) | H_axis drift / (I3 omega3) | "
          "max abs(abs(p)^2 - 1) | steps | first call [s] | run [s] |")
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
