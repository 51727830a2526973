"""Compiled once (issue 12): a repeated plain call of the public API against a jit-compiled run, and the CLI twice.

(a) On the reference case (100 x 6 rod, 6 modes, t1 = 3 s, Dopri8, rtol 1e-10 / atol 1e-12, adjoint):
    the first plain call `fj.value_and_grad(case, x)` (compile + run), then `--runs` plain calls with other
    designs of the same shape (median), against the same computation wrapped by the user in `jax.jit`
    (compiled with `.lower().compile()`, median of `--runs` runs) — all in one process, ratios from that run.
    The same for `fj.objective(case, x)`.
(b) `ffr-jax gradient slider-crank` run twice in fresh processes with an empty persistent-cache directory
    before the first: the wall time of each process and the compile time it reports.

Usage: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/bench_compile_once.py [--runs 3]`.
Writes the section "Compiled once: plain calls and the CLI" of benchmarks/RESULTS.md.
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import jax
import numpy as np

import ffr_jax as fj

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _results import machine, write_section  # noqa: E402


def _timed(fn, *args):
    start = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - start


def _designs(case, n):
    rng = np.random.default_rng(1)
    return [jax.numpy.asarray(rng.uniform(0.3, 0.9, case.n_design)) for _ in range(n)]


def api_timings(runs: int) -> dict:
    case = fj.cases.slider_crank()
    xs = _designs(case, runs + 1)
    out = {}
    for name, plain in (("value_and_grad", lambda x: fj.value_and_grad(case, x)),
                        ("objective", lambda x: fj.objective(case, x))):
        first = _timed(plain, xs[0])
        repeated = [_timed(plain, x) for x in xs[1:]]
        jitted = jax.jit(plain)
        start = time.perf_counter()
        compiled = jitted.lower(xs[0]).compile()
        compile_s = time.perf_counter() - start
        _timed(compiled, xs[0])
        runs_jit = [_timed(compiled, x) for x in xs[1:]]
        out[name] = dict(first_plain_s=first, plain_s=statistics.median(repeated), plain_runs=repeated,
                         jit_compile_s=compile_s, jit_s=statistics.median(runs_jit), jit_runs=runs_jit)
        out[name]["ratio"] = out[name]["plain_s"] / out[name]["jit_s"]
        print(name, out[name], flush=True)
    return out


def cli_timings() -> list[dict]:
    root = pathlib.Path(__file__).parent.parent
    runs = []
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, FFR_JAX_CACHE_DIR=cache, PYTHONPATH=str(root))
        for k in range(2):
            path = pathlib.Path(out) / f"g{k}.json"
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "ffr_jax", "gradient", "slider-crank", "--repeat", "2",
                            "--json", str(path)], env=env, check=True, capture_output=True, text=True)
            wall = time.perf_counter() - start
            timings = json.loads(path.read_text())["timings"]
            runs.append(dict(wall_s=wall, **timings))
            print(f"CLI run {k + 1}: {runs[-1]}", flush=True)
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    api = api_timings(args.runs)
    cli = cli_timings()
    lines = [
        "Command: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/bench_compile_once.py "
        f"--runs {args.runs}`. Machine: {machine()}; default XLA threading.",
        "",
        "Reference case (100 x 6 rod, 588 densities, 6 modes, t1 = 3 s), Dopri8, rtol 1e-10 / atol 1e-12, adjoint "
        "(backward 1e-8 / 1e-10). Plain calls: `fj.value_and_grad(case, x)` as the README shows it, repeated "
        "with other designs of the same shape; jit: the same wrapped by the user in `jax.jit`, compiled first. "
        "Medians of the runs; ratio = plain / jit from the same process.",
        "",
        "| function | first plain call (compile + run) [s] | repeated plain call [s] | jax.jit compile [s] | jax.jit run [s] | plain / jit |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, r in api.items():
        lines.append(f"| `fj.{name}` | {r['first_plain_s']:.1f} | {r['plain_s']:.2f} | {r['jit_compile_s']:.1f} | "
                     f"{r['jit_s']:.2f} | {r['ratio']:.2f} |")
    lines += [
        "",
        "`ffr-jax gradient slider-crank` (adjoint, reference case) twice in fresh processes, persistent compilation "
        "cache in an empty directory before the first run (`FFR_JAX_CACHE_DIR`):",
        "",
        "| run | process wall time [s] | compile (trace or load + XLA) [s] | scene-gradient program | XLA programs loaded / compiled | first call [s] | second call [s] |",
        "|---|---:|---:|---|---:|---:|---:|",
    ]
    for k, r in enumerate(cli):
        cache = r.get("persistent_cache", {})
        program = "loaded (exported)" if r.get("traced_program_loaded") else "traced"
        lines.append(f"| {k + 1} | {r['wall_s']:.1f} | {r['compile_s']:.1f} | {program} | "
                     f"{cache.get('cache_hits', '?')} / {cache.get('cache_misses', '?')} | {r['first_call_s']:.2f} | "
                     f"{r['second_call_s']:.2f} |")
    lines += [
        "",
        "The CLI, like `fj.value_and_grad(case, x)`, compiles the design gradient as cacheable programs "
        "(`ffr_jax/_sensitivity/_cached.py`): the FE stage, the scene gradient (forward and backward solves) and the "
        "FE stage's VJP, each with equinox's checks traced in `nan` mode (no host callbacks: JAX's persistent cache "
        "writes no entry for a program with them) and exported with `jax.export`, so a second run neither traces "
        "nor compiles them (an FE stage with SciPy callbacks is compiled in every process). A failed check (NaN "
        "result) reruns with the checks raising.",
    ]
    write_section("Compiled once: plain calls and the CLI", "\n".join(lines))


if __name__ == "__main__":
    main()
