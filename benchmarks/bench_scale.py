"""Scale: the adjoint gradient from 10^2 to 10^5 design variables (meshes up to 1000 x 100).

Each mesh size runs in a fresh subprocess (so that its peak resident memory is its own) and
measures, for the slider–crank family at `x = 0.5` everywhere:

- `fe`: the FE stage alone, `x -> body data` (assembly, modal reduction, standard input data);
- `fe_vjp`: its forward pass and VJP (what the design gradient adds to the dynamics);
- `dynamics`: the adjoint variable method on the scene (forward simulation, backward adjoint
  ODE, `dpsi/dp`), independent of the mesh size;
- `gradient`: the whole `ffr_jax.value_and_grad(case, x, method="adjoint")`.

Compile time (trace + lower + XLA compile, ahead of time) is separate from run time (median of
`--runs` calls). The sparse FE path runs at every size; the dense path where it fits (up to about
10^3 design variables). Writes `benchmarks/results/scale.{md,json,png}` and the section
`## Scale: 10^2 to 10^5 design variables` of `benchmarks/RESULTS.md`.
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


HERE = pathlib.Path(__file__).resolve().parent
RESULTS_DIR = HERE / "results"
TITLE = "Scale: 10^2 to 10^5 design variables"
# (nx, ny) -> ny (nx - 2) design variables: 100, 1,000, 10,000, 31,472, 99,800.
SIZES = ((27, 4), (102, 10), (252, 40), (564, 56), (1000, 100))
DENSE_MAX_DESIGN = 1000


def _max_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _time_compiled(fn, args, runs):
    """Compile `jax.jit(fn)` ahead of time, then time `runs` calls; returns (compile s, [run s])."""
    import jax

    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - start)
    return compile_s, times


def measure(nx: int, ny: int, fe_path: str, n_modes: int, t1: float, runs: int, rtol: float, atol: float) -> dict:
    """One mesh size and FE path, in this process."""
    rss_start = _max_rss_mb()
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import ffr_jax

    rss_import = _max_rss_mb()
    start = time.perf_counter()
    solver = {"dense": ffr_jax.DenseModes(), "sparse": ffr_jax.LanczosModes()}[fe_path]
    case = ffr_jax.cases.slider_crank(nx, ny, n_modes, t1, modal_solver=solver)
    construct_s = time.perf_counter() - start
    x = case.initial_design(0.5)
    out = {
        "nx": nx, "ny": ny, "fe_path": fe_path, "n_design": case.n_design, "n_dof": case.mesh.n_dof,
        "n_modes": n_modes, "t1": t1, "runs": runs, "construct_s": construct_s,
        "rss_before_import_mb": rss_start, "rss_after_import_mb": rss_import,
    }

    def fe(x):
        return case.body_data(x)

    def fe_vjp(x):
        data, pullback = eqx.filter_vjp(case.body_data, x)
        return pullback(jax.tree.map(jnp.ones_like, data))

    out["fe_compile_s"], out["fe_run_s"] = _time_compiled(fe, (x,), runs)
    out["fe_vjp_compile_s"], out["fe_vjp_run_s"] = _time_compiled(fe_vjp, (x,), runs)
    out["rss_fe_mb"] = _max_rss_mb()

    scene = jax.jit(lambda x: case.scene(x))(x)
    arrays, static = eqx.partition(scene, eqx.is_array)

    def dynamics(arrays):
        return ffr_jax.value_and_grad_scene(case, eqx.combine(arrays, static), method="adjoint", rtol=rtol, atol=atol)

    out["dynamics_compile_s"], out["dynamics_run_s"] = _time_compiled(dynamics, (arrays,), runs)

    def gradient(x):
        return ffr_jax.value_and_grad(case, x, method="adjoint", rtol=rtol, atol=atol)

    out["gradient_compile_s"], out["gradient_run_s"] = _time_compiled(gradient, (x,), runs)
    psi, grad = jax.jit(gradient)(x)
    out["psi"] = float(psi)
    out["max_abs_grad"] = float(jnp.max(jnp.abs(grad)))
    if case.n_design <= DENSE_MAX_DESIGN:
        out["grad"] = [float(g) for g in grad]
    out["rss_peak_mb"] = _max_rss_mb()
    return out


def _median(values):
    return statistics.median(values)


def _table(rows) -> str:
    head = ("| design vars | mesh | dofs | FE path | FE run (s) | FE+VJP run (s) | dynamics run (s) | "
            "gradient run (s) | gradient compile (s) | FE+VJP compile (s) | construct (s) | RSS after FE (MB) | "
            "peak RSS (MB) |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        lines.append(
            f"| {r['n_design']:,} | {r['nx']} x {r['ny']} | {r['n_dof']:,} | {r['fe_path']} | "
            f"{_median(r['fe_run_s']):.3g} | {_median(r['fe_vjp_run_s']):.3g} | {_median(r['dynamics_run_s']):.3g} | "
            f"{_median(r['gradient_run_s']):.3g} | {r['gradient_compile_s']:.3g} | {r['fe_vjp_compile_s']:.3g} | "
            f"{r['construct_s']:.3g} | {r['rss_fe_mb']:.0f} | {r['rss_peak_mb']:.0f} |"
        )
    return "\n".join(lines)


def _plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_mem) = plt.subplots(1, 2, figsize=(11, 4.2))
    for fe_path, style in (("sparse", "-"), ("dense", "--")):
        sel = sorted((r for r in rows if r["fe_path"] == fe_path), key=lambda r: r["n_design"])
        if not sel:
            continue
        n = [r["n_design"] for r in sel]
        ax.loglog(n, [_median(r["gradient_run_s"]) for r in sel], "o" + style, label=f"gradient ({fe_path} FE)")
        ax.loglog(n, [_median(r["fe_vjp_run_s"]) for r in sel], "s" + style, label=f"FE + VJP ({fe_path})")
        if fe_path == "sparse":
            ax.loglog(n, [_median(r["dynamics_run_s"]) for r in sel], "^:", label="dynamics (adjoint, scene)")
        ax_mem.loglog(n, [r["rss_peak_mb"] for r in sel], "o" + style, label=f"peak RSS ({fe_path} FE)")
        ax_mem.loglog(n, [r["rss_fe_mb"] for r in sel], "s" + style, label=f"RSS after FE + VJP ({fe_path})")
    sparse = sorted((r for r in rows if r["fe_path"] == "sparse"), key=lambda r: r["n_design"])
    if sparse:
        n0, t0 = sparse[-1]["n_design"], _median(sparse[-1]["fe_vjp_run_s"])
        ns = [sparse[0]["n_design"], n0]
        ax.loglog(ns, [t0 * m / n0 for m in ns], "k:", lw=0.8, label="slope 1")
    ax.set_xlabel("design variables")
    ax.set_ylabel("run time after compilation (s)")
    ax.set_title("Adjoint gradient, run time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax_mem.set_xlabel("design variables")
    ax_mem.set_ylabel("peak resident memory (MB)")
    ax_mem.set_title("Peak memory (fresh process per size)")
    ax_mem.grid(True, which="both", alpha=0.3)
    ax_mem.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--one", nargs=3, metavar=("NX", "NY", "PATH"), help="(internal) measure one size")
    parser.add_argument("--sizes", default=",".join(f"{nx}x{ny}" for nx, ny in SIZES),
                        help="comma-separated NXxNY meshes")
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--t1", type=float, default=0.3)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--rtol", type=float, default=1e-10)
    parser.add_argument("--atol", type=float, default=1e-12)
    parser.add_argument("--no-write", action="store_true", help="print only; do not write RESULTS.md")
    args = parser.parse_args()

    if args.one:
        nx, ny, fe_path = int(args.one[0]), int(args.one[1]), args.one[2]
        result = measure(nx, ny, fe_path, args.modes, args.t1, args.runs, args.rtol, args.atol)
        print("RESULT " + json.dumps(result))
        return

    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    jobs = []
    for nx, ny in sizes:
        jobs.append((nx, ny, "sparse"))
        if ny * (nx - 2) <= DENSE_MAX_DESIGN:
            jobs.append((nx, ny, "dense"))
    rows = []
    for nx, ny, fe_path in jobs:
        cmd = [sys.executable, __file__, "--one", str(nx), str(ny), fe_path, "--modes", str(args.modes),
               "--t1", str(args.t1), "--runs", str(args.runs), "--rtol", str(args.rtol), "--atol", str(args.atol)]
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ))
        if proc.returncode != 0:
            print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
            raise SystemExit(f"size {nx} x {ny} ({fe_path}) failed")
        result = json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))[7:])
        rows.append(result)
        print(f"{nx} x {ny} {fe_path}: n_design {result['n_design']}, gradient {_median(result['gradient_run_s']):.3g} s "
              f"(compile {result['gradient_compile_s']:.3g} s), FE+VJP {_median(result['fe_vjp_run_s']):.3g} s, "
              f"dynamics {_median(result['dynamics_run_s']):.3g} s, peak RSS {result['rss_peak_mb']:.0f} MB "
              f"[{time.perf_counter() - start:.0f} s wall]", flush=True)

    table = _table(rows)
    print(table)
    if args.no_write:
        return
    RESULTS_DIR.mkdir(exist_ok=True)
    (RESULTS_DIR / "scale.json").write_text(json.dumps(rows, indent=1))
    _plot(rows, RESULTS_DIR / "scale.png")
    sys.path.insert(0, str(HERE))
    from _results import machine, write_section

    largest = max((r for r in rows if r["fe_path"] == "sparse"), key=lambda r: r["n_design"])
    same = [r for r in rows if r["fe_path"] == "sparse" and any(
        d["fe_path"] == "dense" and d["n_design"] == r["n_design"] for d in rows)]
    def _dense(r):
        return next(d for d in rows if d["fe_path"] == "dense" and d["n_design"] == r["n_design"])

    def _grad_diff(r):
        a, b = r.get("grad"), _dense(r).get("grad")
        if not a or not b:
            return float("nan")
        return max(abs(u - v) for u, v in zip(a, b)) / max(abs(v) for v in b)

    psi_check = "; ".join(
        f"{r['n_design']:,} variables: psi {r['psi']:.10g} (sparse) vs {_dense(r)['psi']:.10g} (dense), "
        f"gradient max difference {_grad_diff(r):.1e} of max |grad|"
        for r in same)
    blas = os.environ.get("OPENBLAS_NUM_THREADS")
    command = " ".join(([f"OPENBLAS_NUM_THREADS={blas}"] if blas else [])
                       + ["flock /tmp/ffr_bench.lock python benchmarks/bench_scale.py"] + sys.argv[1:])
    body = f"""Command: `{command}`

Slider–crank family (REFERENCE_CASE.md §5) at `x = 0.5`, {args.modes} modes, **short horizon
t1 = {args.t1} s** (the dynamics cost does not depend on the mesh, only on the horizon and the
retained frequencies; the full 3 s horizon multiplies the `dynamics` column by about
{3.0 / args.t1:.0f}), forward rtol {args.rtol:g} / atol {args.atol:g}, adjoint method with its default
backward tolerances. Each size in a fresh process; run times are medians of {args.runs} calls
after ahead-of-time compilation; RSS is the process maximum resident memory (JAX runtime
included: about {rows[0]['rss_after_import_mb']:.0f} MB after import) after the FE stage and its VJP
ran ("after FE") and at the end ("peak", which includes compiling the adjoint gradient: XLA's
compiler, not the mesh, sets it on small meshes). Machine: {machine()}; shared with other
sessions, so absolute times are noisy — compare within a row.

{table}

- FE run: `x -> body data`; FE+VJP: the same with its VJP (the FE share of the gradient);
  dynamics: `value_and_grad_scene` by the adjoint method (forward + backward ODE); gradient: the
  whole `value_and_grad(case, x, method="adjoint")` = FE+VJP + dynamics.
- At {largest['n_design']:,} design variables ({largest['nx']} x {largest['ny']} mesh, {largest['n_dof']:,}
  dofs): gradient **{_median(largest['gradient_run_s']):.1f} s** after compilation
  (target <= 60 s), of which the FE stage with its VJP {_median(largest['fe_vjp_run_s']):.1f} s; compile
  {largest['gradient_compile_s']:.0f} s; peak memory {largest['rss_peak_mb']:.0f} MB ({largest['rss_fe_mb']:.0f} MB after the FE stage).
- Sparse vs dense at equal size: {psi_check}.
- Figure: `benchmarks/results/scale.png` (log–log run time and peak memory against design
  variables); raw numbers `benchmarks/results/scale.json`.
"""
    (RESULTS_DIR / "scale.md").write_text(f"# {TITLE}\n\n{body}")
    write_section(TITLE, body)


if __name__ == "__main__":
    main()
