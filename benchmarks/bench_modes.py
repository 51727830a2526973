"""Forward solve of the reference slider–crank versus retained modes, explicit and stiff solvers (issue 15).

For each number of retained modes (default 6, 10, 15, 20, 30, 40) and each solver (Dopri8; the
Rosenbrock methods of `ffr_jax._solver`: Rodas5P, Rodas4; diffrax's Kvaerno5) over a tolerance
sweep (atol = 1e-2 rtol): steps (attempted, accepted), compile time, median run time and the psi
error against a tight reference (Dopri8 at rtol 1e-12, atol 1e-14: explicit, independent of the
stiff route, and resolving every retained mode). Each mode count runs in its own process (compile
time and peak memory are its own).

With `--breakdown`, what one Rosenbrock step costs at each mode count, measured in compiled loops:
one evaluation of the vector field, its Jacobian as the solver forms it (one `jax.linearize` and a
`vmap` over the unit tangents), the LU factorisation of the `(2f + 1)`-square stage matrix and one
solve with it.

Usage (timings on the shared machine: under `flock`):
```
flock /tmp/ffr_bench.lock python benchmarks/bench_modes.py                     # all, writes results
python benchmarks/bench_modes.py --modes 6 30 --solvers rodas5p --rtols 1e-6 --runs 1 --no-write
```
Writes `benchmarks/results/modes_forward.json` (raw rows) and `modes_forward.md` (tables).
"""

import argparse
import json
import os
import pathlib
import resource
import statistics
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).parent
RESULTS = HERE / "results"
REFERENCE_RTOL = 1e-12
SOLVERS = ("dopri8", "rodas5p", "rodas4", "kvaerno5")
DEFAULT_RTOLS = {
    "dopri8": (1e-6, 1e-8, 1e-10),
    "rodas5p": (1e-6, 1e-7, 1e-8, 1e-10),
    "rodas4": (1e-6, 1e-8),
    "kvaerno5": (1e-6,),
}


def _solver(name):
    import diffrax

    from ffr_jax._solver import Rodas4, Rodas5P

    return {"dopri8": diffrax.Dopri8, "rodas5p": Rodas5P, "rodas4": Rodas4, "kvaerno5": diffrax.Kvaerno5}[name]()


def _forward(case, solver, max_steps):
    """`(scene, rtol, atol) -> (psi, steps, accepted)`, compiled once (tolerances are traced)."""
    import equinox as eqx

    import ffr_jax

    @eqx.filter_jit
    def run(scene, rtol, atol):
        traj = ffr_jax.simulate(case.model, scene, case.t0, case.t1, case.y_r0, case.z_r0, integrand=case.integrand,
                                solver=solver, rtol=rtol, atol=atol, max_steps=max_steps, jump_ts=case.jump_ts)
        return traj.psi, traj.num_steps, traj.num_accepted_steps

    return run


def _loop_cost(fn, arg, n=200, rounds=5):
    """Microseconds per call of `fn(i, arg) -> array like arg-independent output` in a compiled loop."""
    import jax
    import jax.numpy as jnp

    @jax.jit
    def loop(arg):
        def body(i, acc):
            return acc + jnp.sum(fn(i, arg))
        return jax.lax.fori_loop(0, n, body, jnp.zeros(()))

    jax.block_until_ready(loop(arg))
    samples = []
    for _ in range(rounds):
        start = time.perf_counter()
        jax.block_until_ready(loop(arg))
        samples.append(time.perf_counter() - start)
    return min(samples) / n * 1e6


def breakdown(case, scene):
    """Microseconds of the pieces of one Rosenbrock step on this case (compiled loops, best of 5)."""
    import jax
    import jax.flatten_util
    import jax.numpy as jnp
    import jax.scipy.linalg as jsl

    f = case.model.partition.n_independent
    n = 2 * f + 1
    # A state along the reference motion (t = 1.5 s) so that the Newton iteration does real work.
    traj = jax.jit(lambda s: __import__("ffr_jax").simulate(
        case.model, s, case.t0, 1.5, case.y_r0, case.z_r0, integrand=case.integrand, rtol=1e-6, atol=1e-8,
        jump_ts=case.jump_ts))(scene)
    u0 = jnp.concatenate([traj.ys[-1], traj.zs[-1], traj.psi[None]])

    def field(t, u):
        y_r, _, zdot = case.model.state_and_accelerations(t, u[:f], u[f:2 * f], scene)
        return jnp.concatenate([u[f:2 * f], zdot, case.integrand(t, y_r, scene)[None]])

    def one_field(i, u):
        return field(1.5 + i * 1e-6, u)

    def one_jacobian(i, u):
        _, linear = jax.linearize(field, 1.5 + i * 1e-6, u)
        tangents_t = jnp.zeros(n + 1).at[n].set(1.0)
        tangents_u = jnp.concatenate([jnp.eye(n), jnp.zeros((1, n))])
        return jax.vmap(linear)(tangents_t, tangents_u)

    jac = jax.jit(lambda u: jax.jacfwd(field, argnums=1)(1.5, u))(u0)
    matrix = jnp.eye(n) / 0.2119 - 1e-3 * jac

    def one_lu(i, m):
        return jsl.lu_factor(m + i * 1e-12)[0]

    lu = jsl.lu_factor(matrix)

    def one_solve(i, b):
        return jsl.lu_solve(lu, b + i * 1e-12)

    out = {
        "field_us": _loop_cost(one_field, u0),
        "jacobian_us": _loop_cost(one_jacobian, u0, n=50),
        "lu_us": _loop_cost(one_lu, matrix),
        "solve_us": _loop_cost(one_solve, u0),
        "state_size": n,
    }
    # Rodas5P: 1 Jacobian (whose primal is stage 1), 7 more evaluations, 1 LU, 8 solves per step.
    out["rodas5p_step_us"] = out["jacobian_us"] + 7 * out["field_us"] + out["lu_us"] + 8 * out["solve_us"]
    return out


def worker(spec: dict) -> dict:
    """All rows of one mode count (run in a fresh process)."""
    import jax
    import jax.numpy as jnp

    import ffr_jax

    n_modes = spec["modes"]
    start = time.perf_counter()
    case = ffr_jax.cases.slider_crank(n_modes=n_modes)
    x = case.initial_design(0.5)
    scene = case.scene(x)
    out = {"modes": n_modes, "f_max_hz": float(case.frequencies(x)[-1]), "construct_s": time.perf_counter() - start,
           "rows": []}
    reference = spec.get("reference_psi")
    if reference is None:
        run = _forward(case, _solver("dopri8"), 2_000_000)
        start = time.perf_counter()
        psi, steps, _ = jax.block_until_ready(run(scene, jnp.asarray(REFERENCE_RTOL), jnp.asarray(REFERENCE_RTOL * 1e-2)))
        reference = float(psi)
        out["reference"] = {"psi": reference, "steps": int(steps), "wall_s": time.perf_counter() - start}
    out["reference_psi"] = reference
    for name in spec["solvers"]:
        run = _forward(case, _solver(name), spec["max_steps"])
        compiled = None
        for rtol in spec["rtols"][name]:
            args = (scene, jnp.asarray(rtol), jnp.asarray(rtol * 1e-2))
            row = {"solver": name, "rtol": rtol}
            try:
                if compiled is None:
                    start = time.perf_counter()
                    compiled = run.lower(*args).compile() if hasattr(run, "lower") else None
                    row["compile_s"] = time.perf_counter() - start
                call = compiled if compiled is not None else run
                start = time.perf_counter()
                psi, steps, accepted = jax.block_until_ready(call(*args))
                first = time.perf_counter() - start
                samples = [first]
                if first < spec["slow_s"]:
                    for _ in range(spec["runs"] - 1):
                        start = time.perf_counter()
                        jax.block_until_ready(call(*args))
                        samples.append(time.perf_counter() - start)
                row.update(psi=float(psi), steps=int(steps), accepted=int(accepted),
                           run_s=statistics.median(samples), runs=len(samples),
                           psi_rel_error=abs(float(psi) - reference) / abs(reference))
            except Exception as error:  # noqa: BLE001 - a failed solve is a row of the table
                row["error"] = f"{type(error).__name__}: {str(error).splitlines()[0][:120]}"
            out["rows"].append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
    if spec["breakdown"]:
        out["breakdown"] = breakdown(case, scene)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["load"] = os.getloadavg()
    return out


def _fmt(x, spec=".3g"):
    return "–" if x is None else format(x, spec)


def markdown(data: dict) -> str:
    lines = [f"Command: `{data['command']}`", "", f"Machine: {data['machine']}; {data['threads']}.", "",
             "| modes | f_max [Hz] | solver | rtol | steps (accepted) | compile [s] | run [s] | psi rel. error |",
             "|---:|---:|---|---:|---:|---:|---:|---:|"]
    for block in data["modes"]:
        for row in block["rows"]:
            if "error" in row:
                lines.append(f"| {block['modes']} | {block['f_max_hz']:.0f} | {row['solver']} | {row['rtol']:g} | "
                             f"{row['error']} | | | |")
                continue
            lines.append(f"| {block['modes']} | {block['f_max_hz']:.0f} | {row['solver']} | {row['rtol']:g} | "
                         f"{row['steps']} ({row['accepted']}) | {_fmt(row.get('compile_s'), '.1f')} | "
                         f"{row['run_s']:.3f} | {row['psi_rel_error']:.1e} |")
    if any("breakdown" in b for b in data["modes"]):
        lines += ["", "Per-step pieces of a Rosenbrock step (compiled loops, best of 5, microseconds):", "",
                  "| modes | state size | field | Jacobian (linearize + vmap) | LU | solve | Rodas5P step (J + 7 f + LU + 8 solves) |",
                  "|---:|---:|---:|---:|---:|---:|---:|"]
        for block in data["modes"]:
            b = block.get("breakdown")
            if b:
                lines.append(f"| {block['modes']} | {b['state_size']} | {b['field_us']:.1f} | {b['jacobian_us']:.0f} | "
                             f"{b['lu_us']:.1f} | {b['solve_us']:.1f} | {b['rodas5p_step_us']:.0f} |")
    lines += ["", "References (Dopri8, rtol 1e-12, atol 1e-14): " + "; ".join(
        f"{b['modes']} modes psi = {b['reference_psi']:.12e}" + (f" ({b['reference']['steps']} steps)" if "reference" in b else "")
        for b in data["modes"])]
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[6, 10, 15, 20, 30, 40])
    parser.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=SOLVERS)
    parser.add_argument("--rtols", type=float, nargs="+", default=None, help="the same sweep for every solver")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--slow-s", type=float, default=20.0, help="a first run slower than this is not repeated")
    parser.add_argument("--max-steps", type=int, default=400_000)
    parser.add_argument("--breakdown", action="store_true")
    parser.add_argument("--timeout", type=float, default=3600.0, help="per mode count")
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(json.loads(args.worker))))
        return
    previous = {}
    path = RESULTS / "modes_forward.json"
    if path.exists():  # reuse the references (slow at many modes)
        previous = {b["modes"]: b["reference_psi"] for b in json.loads(path.read_text()).get("modes", [])}
    rtols = {s: tuple(args.rtols) if args.rtols else DEFAULT_RTOLS[s] for s in args.solvers}
    data = {"command": "python benchmarks/bench_modes.py " + " ".join(sys.argv[1:]), "modes": [],
            "threads": "XLA_FLAGS=" + os.environ.get("XLA_FLAGS", "(default)")}
    for n_modes in args.modes:
        spec = {"modes": n_modes, "solvers": args.solvers, "rtols": rtols, "runs": args.runs, "slow_s": args.slow_s,
                "max_steps": args.max_steps, "breakdown": args.breakdown, "reference_psi": previous.get(n_modes)}
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, __file__, "--worker", json.dumps(spec)], capture_output=True, text=True,
                              timeout=args.timeout, env={**os.environ, "PYTHONPATH": str(HERE.parent)})
        if proc.returncode != 0:
            print(proc.stderr[-3000:], file=sys.stderr)
            raise SystemExit(f"worker for {n_modes} modes failed")
        block = json.loads(proc.stdout.strip().splitlines()[-1])
        print(f"{n_modes} modes done in {time.perf_counter() - start:.0f} s: " + json.dumps(block), flush=True)
        data["modes"].append(block)
    import _results

    data["machine"] = _results.machine()
    text = markdown(data)
    print(text)
    if not args.no_write:
        RESULTS.mkdir(exist_ok=True)
        path.write_text(json.dumps(data, indent=1))
        (RESULTS / "modes_forward.md").write_text(text)


if __name__ == "__main__":
    main()
