"""Forward simulation of the reference slider–crank: speed and convergence of psi (issue 3).

(a) Speed at the paper's tolerances (rtol 1e-10, atol 1e-12), for Dopri8 (the default solver) and
    Tsit5: compile time, median run time over `--runs` runs after a warm-up (`block_until_ready`),
    steps, and the cost of one evaluation of the vector field (the minimal equations of motion with
    the compliance integrand) inside a compiled loop. Optionally a scipy DOP853 solve of the same
    model calling the jitted vector field from Python, timed in the same run, for an honest ratio.
(b) Convergence of psi for rtol = 1e-6 ... 1e-12 with atol = 1e-2 rtol, for Kvaerno5 (implicit),
    Tsit5 and Dopri8 (explicit): psi, |psi - psi_ref| (psi_ref: Dopri8 at rtol 1e-13, atol 1e-15),
    steps and wall time. Solves that exhaust `--max-steps` are reported as such.

Usage: `python benchmarks/bench_forward.py [--runs 3] [--no-scipy] [--max-steps 200000]`; run timing
benchmarks under `flock /tmp/ffr_bench.lock` on the shared machine. Writes
`benchmarks/results/forward.md` and the section "Forward simulation" of `benchmarks/RESULTS.md`.
"""

import argparse
import pathlib
import statistics
import sys
import time

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax

HERE = pathlib.Path(__file__).parent
SCIPY_REFERENCE_S = 6.0  # scipy DOP853 of the same model on this machine (issue 3)


def _forward(case, solver, max_steps):
    """`scene, rtol, atol -> (psi, steps)` compiled once per solver (tolerances are traced)."""

    @eqx.filter_jit
    def traced(scene, rtol, atol):
        traj = ffr_jax.simulate(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0,
                                integrand=case.integrand, solver=solver, rtol=rtol, atol=atol,
                                max_steps=max_steps, jump_ts=case.jump_ts)
        return traj.psi, traj.num_steps

    def run(scene, rtol, atol):
        return traced(scene, jnp.asarray(rtol), jnp.asarray(atol))

    return run


def _vector_field(case):
    """The vector field of the simulated ODE, `(t, (y, z, psi), scene) -> d/dt (y, z, psi)`."""

    def field(t, y, z, scene):
        y_r, _, zdot = case.model.state_and_accelerations(t, y, z, scene)
        return z, zdot, case.integrand(t, y_r, scene)

    return field


def _rhs_cost(case, scene, n=5000, rounds=5):
    """Microseconds per vector-field evaluation inside a compiled loop (state carried, nothing hoisted)."""
    field = _vector_field(case)

    @jax.jit
    def loop(scene):
        def body(i, carry):
            (y, z), scene = carry
            ydot, zdot, _ = field(i * (1.0 / n), y, z, scene)
            return (y + 1e-6 * ydot, z + 1e-6 * zdot), scene

        y0 = jnp.zeros(case.model.partition.n_independent)
        return jax.lax.fori_loop(0, n, body, ((y0, y0), scene))[0]

    jax.block_until_ready(loop(scene))
    samples = []
    for _ in range(rounds):
        start = time.perf_counter()
        jax.block_until_ready(loop(scene))
        samples.append(time.perf_counter() - start)
    return min(samples) / n * 1e6


def _time_forward(run, scene, rtol, atol, runs):
    start = time.perf_counter()
    psi, steps = jax.block_until_ready(run(scene, rtol, atol))  # compile + first run
    first = time.perf_counter() - start
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        psi, steps = jax.block_until_ready(run(scene, rtol, atol))
        samples.append(time.perf_counter() - start)
    median = statistics.median(samples)
    return float(psi), int(steps), first - median, median, min(samples)


def _scipy_dop853(case, scene, rtol, atol):
    """scipy DOP853 on the same ODE, the vector field jitted and called from Python."""
    import scipy.integrate

    field = jax.jit(_vector_field(case))
    f = case.model.partition.n_independent

    def rhs(t, s):
        ydot, zdot, fdot = field(t, s[:f], s[f:2 * f], scene)
        return np.concatenate([np.asarray(ydot), np.asarray(zdot), np.asarray(fdot)[None]])

    s0 = np.zeros(2 * f + 1)
    rhs(0.0, s0)  # compile
    start = time.perf_counter()
    sols = []
    jumps = tuple(j for j in case.jump_ts if case.t0 < j < case.t1)
    for a, b in zip((case.t0, *jumps), (*jumps, case.t1)):  # restart where the crank law switches pieces
        sol = scipy.integrate.solve_ivp(rhs, (a, b), s0, method="DOP853", rtol=rtol, atol=atol)
        s0 = sol.y[:, -1]
        sols.append(sol)
    wall = time.perf_counter() - start
    return float(s0[-1]), sum(s.nfev for s in sols), wall


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=200_000)
    parser.add_argument("--no-scipy", action="store_true")
    parser.add_argument("--out", type=pathlib.Path, default=HERE / "results" / "forward.md")
    args = parser.parse_args()

    case = ffr_jax.cases.slider_crank()
    scene = eqx.filter_jit(lambda c, x: c.scene(x))(case, case.initial_design(0.5))
    scene = jax.block_until_ready(scene)
    solvers = {"Dopri8": diffrax.Dopri8(), "Tsit5": diffrax.Tsit5(), "Kvaerno5": diffrax.Kvaerno5()}
    runs = {name: _forward(case, s, args.max_steps) for name, s in solvers.items()}

    rhs_us = _rhs_cost(case, scene)
    speed = []
    for name in ("Dopri8", "Tsit5"):
        psi, steps, compile_s, median, fastest = _time_forward(runs[name], scene, 1e-10, 1e-12, args.runs)
        speed.append((name, compile_s, median, fastest, steps, psi))
        print(f"{name}: compile {compile_s:.1f} s, run median {median:.3f} s (fastest {fastest:.3f}), "
              f"{steps} steps, psi {psi:.10f}", flush=True)
    scipy_row = None
    if not args.no_scipy:
        scipy_row = _scipy_dop853(case, scene, 1e-10, 1e-12)
        print(f"scipy DOP853: {scipy_row[2]:.2f} s, {scipy_row[1]} evaluations, psi {scipy_row[0]:.10f}", flush=True)

    psi_ref, ref_steps = jax.block_until_ready(runs["Dopri8"](scene, 1e-13, 1e-15))
    psi_ref, ref_steps = float(psi_ref), int(ref_steps)
    table = []
    for name in ("Kvaerno5", "Tsit5", "Dopri8"):
        try:  # compile once per solver, outside the timed rows
            jax.block_until_ready(runs[name](scene, 1e-6, 1e-8))
        except eqx.EquinoxRuntimeError:
            pass
        for k in range(6, 13):
            rtol = 10.0 ** -k
            start = time.perf_counter()
            try:
                psi, steps = jax.block_until_ready(runs[name](scene, rtol, 1e-2 * rtol))
                row = (name, rtol, float(psi), abs(float(psi) - psi_ref), int(steps), time.perf_counter() - start)
            except eqx.EquinoxRuntimeError:
                row = (name, rtol, None, None, args.max_steps, time.perf_counter() - start)
            table.append(row)
            print(row, flush=True)

    machine_line = None
    sys.path.insert(0, str(HERE))
    from _results import machine, write_section
    machine_line = machine()
    dop = speed[0]
    lines = [
        "Command: `flock /tmp/ffr_bench.lock python benchmarks/bench_forward.py"
        + (" --no-scipy" if args.no_scipy else "") + "` (details: `benchmarks/results/forward.md`)",
        "",
        f"- {machine_line}; a shared 2-core machine: wall times are noisy, ratios are from one run",
        "- reference slider–crank (100 x 6 mesh, 6 modes, t1 = 3 s, x = 0.5), rtol 1e-10, atol 1e-12; "
        f"median of {args.runs} runs after the first (compile = first call - median)",
        f"- one evaluation of the vector field (minimal equations of motion + compliance) in a compiled loop: "
        f"{rhs_us:.1f} us",
        "",
        "| solver | compile [s] | run, median [s] | run, fastest [s] | steps | psi | scipy DOP853 (6 s) / run |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, c, m, f, steps, psi in speed:
        lines.append(f"| {name} | {c:.1f} | {m:.3f} | {f:.3f} | {steps} | {psi:.10g} | {SCIPY_REFERENCE_S / m:.1f} |")
    if scipy_row is not None:
        lines += ["", f"scipy DOP853 (`solve_ivp`, the jitted vector field called from Python, restarted at t = 2), "
                  f"same run: {scipy_row[2]:.2f} s, {scipy_row[1]} evaluations, psi {scipy_row[0]:.10f}; "
                  f"ratio scipy / Dopri8 = {scipy_row[2] / dop[2]:.1f}."]
    lines += ["", "Convergence of psi, atol = 1e-2 rtol; psi_ref = Dopri8 at rtol 1e-13, atol 1e-15 "
              f"({psi_ref:.12g}, {ref_steps} steps); wall time of one compiled run (tolerances are "
              "traced, each solver compiled once beforehand).", "",
              "| solver | rtol | psi | abs(psi - psi_ref) | steps | wall [s] |", "|---|---:|---:|---:|---:|---:|"]
    for name, rtol, psi, err, steps, wall in table:
        if psi is None:
            lines.append(f"| {name} | {rtol:.0e} | max_steps ({steps}) exhausted | | | {wall:.1f} |")
        else:
            lines.append(f"| {name} | {rtol:.0e} | {psi:.12g} | {err:.2e} | {steps} | {wall:.2f} |")
    body = "\n".join(lines)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("# Forward simulation of the reference slider–crank\n\n" + body + "\n")
    write_section("Forward simulation of the reference slider–crank", body)


if __name__ == "__main__":
    main()
