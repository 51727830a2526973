"""Compile time of the public entry points on the shipped cases: first call, its split, a later call, and
the first call of a second process with JAX's persistent compilation cache (issue 28).

For each target two fresh processes run one after the other, sharing a new, empty cache directory
(`JAX_COMPILATION_CACHE_DIR`, every program written: minimum compile time and entry size 0):
the first fills it, the second shows what it saves. Each process times the first call (compile and
run; tracing, lowering and XLA summed from `jax.monitoring`) and one later call at another design
(or another parameter value), and counts the cache's hits and misses.

    python benchmarks/bench_compile_time.py                       # every target, writes the RESULTS section
    python benchmarks/bench_compile_time.py --targets readme-gradient reference-gradient
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).parent


def _readme_problem(fj, np):
    bar = lambda m, l: fj.rigid_body_data(m, (m * l / 2, 0.0), m * l**2 / 3, [[0, 0], [l, 0]])  # noqa: E731
    scene = fj.Scene(
        bodies=(fj.Body("crank", bar(0.5, 0.1)), fj.Body("arm", bar(1.0, 0.4))),
        constraints=(fj.GroundRevolute(body=0, marker=0),
                     fj.AngleDriver(body=0, angle=fj.RampLaw(t_ramp=0.5, angle_at_ramp=np.pi / 2, speed=2 * np.pi)),
                     fj.Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0)),
        forces=(fj.SpringDamper(1, 1, stiffness=200.0, damping=2.0, rest_length=0.3, ground_point=(0.3, -0.3)),
                fj.AppliedForce(1, 1, magnitude=fj.HarmonicLaw(5.0, 2.0), direction=(0.0, 1.0)), fj.Gravity()),
    )
    return fj.Problem(scene, 1.0, positions=(0.0, 0.0, 0.0, 0.1, 0.0, -np.pi / 2), velocities=[0.5],
                      objective=fj.Objective(integrand=fj.KineticEnergy()))


def _calls(target: str):
    """`(first, later)`: two calls of the target's entry point with equal shapes and other values."""
    import numpy as np

    import ffr_jax as fj

    def design_pair(case, call):
        x = case.initial_design(0.5)
        other = x * 0.9 if not isinstance(x, dict) else {k: v * 0.9 for k, v in x.items()}
        return (lambda: call(case, x)), (lambda: call(case, other))

    if target == "readme-gradient":
        problem = _readme_problem(fj, np)
        scene = problem.scene
        other = problem.with_scene(eqx_tree_at(lambda s: s.forces[0].stiffness, scene, 250.0))
        return (lambda: fj.value_and_grad(problem)), (lambda: fj.value_and_grad(other))
    case_name, _, entry = target.rpartition("-")
    cases = {"reference": fj.cases.slider_crank, "four-bar": fj.cases.four_bar,
             "link-four-bar": fj.cases.link_four_bar, "two-links": fj.cases.four_bar_two_links,
             "pendulum": fj.cases.flexible_pendulum, "spinning-beam": fj.cases.spinning_beam}
    case = cases[case_name]()
    calls = {"gradient": lambda c, x: fj.value_and_grad(c, x),
             "adjoint": lambda c, x: fj.value_and_grad(c, x, "adjoint"),
             "objective": lambda c, x: fj.objective(c, x),
             "simulate": lambda c, x: fj.simulate(c, x)}
    return design_pair(case, calls[entry])


def eqx_tree_at(where, tree, value):
    import equinox as eqx
    import jax.numpy as jnp

    return eqx.tree_at(where, tree, jnp.asarray(value))


def measure(target: str) -> dict:
    import jax
    import jax.monitoring as monitoring

    durations: dict[str, float] = {}
    counts: dict[str, int] = {}
    monitoring.register_event_duration_secs_listener(
        lambda event, duration, **kw: durations.__setitem__(event, durations.get(event, 0.0) + duration))
    monitoring.register_event_listener(lambda event, **kw: counts.__setitem__(event, counts.get(event, 0) + 1))
    first, later = _calls(target)
    start = time.perf_counter()
    jax.block_until_ready(first())
    first_s = time.perf_counter() - start
    split = {name: durations.get(f"/jax/core/compile/{event}", 0.0) for name, event in
             (("trace", "jaxpr_trace_duration"), ("lower", "jaxpr_to_mlir_module_duration"),
              ("xla", "backend_compile_duration"))}
    start = time.perf_counter()
    jax.block_until_ready(later())
    return dict(target=target, first=first_s, later=time.perf_counter() - start, **split,
                hits=counts.get("/jax/compilation_cache/cache_hits", 0),
                misses=counts.get("/jax/compilation_cache/cache_misses", 0), load=os.getloadavg()[0])


TARGETS = ("reference-gradient", "reference-adjoint", "reference-objective", "reference-simulate", "readme-gradient",
           "four-bar-gradient",
           "link-four-bar-gradient", "two-links-gradient", "pendulum-gradient", "spinning-beam-gradient")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--measure")
    parser.add_argument("--targets", nargs="+", default=list(TARGETS))
    parser.add_argument("--section", default="Compile time",
                        help="the RESULTS section to write (a later run beside an earlier one: another name)")
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure)))
        return
    rows = []
    for target in args.targets:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": cache, "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
                   "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0",
                   # the package's kept programs (issue 28) in the same new directory
                   "FFR_JAX_CACHE_DIR": cache}
            env.pop("FFR_JAX_NO_CACHE", None)
            pair = []
            for _ in range(2):
                out = subprocess.run([sys.executable, __file__, "--measure", target], capture_output=True, text=True,
                                     env=env)
                if out.returncode:
                    raise RuntimeError(f"{target}: {out.stderr[-2000:]}")
                pair.append(json.loads(out.stdout.strip().splitlines()[-1]))
            rows.append(pair)
            print(pair, flush=True)
    sys.path.insert(0, str(HERE))
    from _results import machine, write_section

    lines = [
        f"Command: `python benchmarks/bench_compile_time.py --targets {' '.join(args.targets)}` (two fresh processes per",
        "target, one after the other, with a new, empty cache directory shared by the two: JAX's persistent",
        f"compilation cache and the package's kept programs). Machine: {machine()}; default XLA settings.",
        "",
        "Targets: `reference-gradient` `fj.value_and_grad(fj.cases.slider_crank(), x)` with no options (the default",
        "route: the discrete adjoint of Rodas5P), `reference-adjoint` the same with `method=\"adjoint\"` (the default",
        "before issue 28: Dopri8, rtol 1e-10), `reference-objective` `fj.objective(case, x)`, `reference-simulate`",
        "`fj.simulate(case, x)` (its default output: the state at t1), `readme-gradient`",
        "`fj.value_and_grad(problem)` of the README's own mechanism, `<case>-gradient` `fj.value_and_grad(case, x)` of",
        "the other shipped cases with their default arguments. Later call: another design (or spring constant).",
        "",
        "| target | first call [s] | trace / lower / XLA [s] | later call [s] | second process: first call [s] |"
        " its trace / lower / XLA [s] | its cache hits / misses | load |",
        "|---|---:|---|---:|---:|---|---:|---:|",
    ]
    for one, two in rows:
        lines.append(
            f"| {one['target']} | {one['first']:.1f} | {one['trace']:.1f} / {one['lower']:.1f} / {one['xla']:.1f} | "
            f"{one['later']:.2f} | {two['first']:.1f} | {two['trace']:.1f} / {two['lower']:.1f} / {two['xla']:.1f} | "
            f"{two['hits']} / {two['misses']} | {one['load']:.1f} |")
    write_section(args.section, "\n".join(lines))


if __name__ == "__main__":
    main()
