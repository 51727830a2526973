"""The FE stage of a designed body on an unstructured mesh of about 10^5 quadrilaterals.

A link with two pin holes (gmsh, `ffr_jax._design.link_with_holes`), QM6 elements, SIMP at
`x = 0.5`, clamped at hole A, a rigid interface at hole B (3 static modes), 6 eigenmodes by
`LanczosModes`, markers at both pin centres. Stages (host stages timed directly, compiled ones
with compile time separate, medians of several runs after a warm-up):

1. gmsh meshing; the `QuadMesh` checks alone (orientation, Jacobians, duplicates); the element
   matrices (`FEModel`); a density filter of radius 2 mean element sizes;
2. host assembly of the CSC matrices `K_II`, `M_II` (one `bincount` each on a cached pattern);
3. the matrix-free product `K @ Phi` (compiled);
4. the modal basis `x -> Phi` (compiled; host Lanczos inside);
5. the forward map `x -> body data`;
6. its VJP: the gradient of a span-invariant scalar of the body data with respect to all
   design variables.

Peak resident memory (`ru_maxrss`) is read after each stage (cumulative over the process).
Writes the section "FE stage on unstructured meshes" of `benchmarks/RESULTS.md` (with `--write`).

Usage: `OPENBLAS_NUM_THREADS=1 flock /tmp/ffr_bench.lock python benchmarks/bench_design_fe.py [--mesh-size 0.00034] [--runs 3] [--write]`

On a shared CPU, OpenBLAS threads in ARPACK's level-2 BLAS spin against other processes: on a
loaded 2-core machine the host Lanczos of a 24,000-dof link took 3.2 s with default threading
and 0.86 s with `OPENBLAS_NUM_THREADS=1`.
"""

import argparse
import os
import resource
import statistics
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax._design as fd

sys.path.insert(0, os.path.dirname(__file__))
from _results import machine, write_section  # noqa: E402


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _time_host(f, runs):
    f()
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        f()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def _time_compiled(f, args, runs):
    start = time.perf_counter()
    compiled = eqx.filter_jit(f).lower(*args).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(*args))
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        samples.append(time.perf_counter() - start)
    return compile_s, statistics.median(samples)


def _invariant(body, x):
    d = body.body_data(x)
    mq_inv = jnp.linalg.inv(d.modal_mass)
    return (jnp.trace(mq_inv @ d.modal_stiffness) * 1e-8 + jnp.sum(d.modal_moment @ mq_inv @ d.modal_moment.T)
            + jnp.sum(d.marker_modes**2))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-size", type=float, default=0.00034)
    parser.add_argument("--modes", type=int, default=6)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--write", action="store_true", help="write the section of RESULTS.md")
    args = parser.parse_args()
    rows = []

    def row(stage, compile_s, run_s):
        rows.append((stage, compile_s, run_s, _peak_mb()))
        c = "" if compile_s is None else f"{compile_s:.2f}"
        print(f"{stage:60s} compile {c:>6s} s  run {run_s:8.3f} s  peak RSS {_peak_mb():8.0f} MB", flush=True)

    start = time.perf_counter()
    link = fd.link_with_holes(length=0.2, width=0.05, hole_radius=0.008, rim_width=0.005, mesh_size=args.mesh_size)
    row("gmsh meshing (quads) + QuadMesh checks", None, time.perf_counter() - start)
    mesh = link.mesh
    row("QuadMesh checks alone", None, _time_host(lambda: fd.QuadMesh(mesh.nodes, mesh.elements), args.runs))
    start = time.perf_counter()
    model = fd.FEModel(mesh, fd.QM6(), 0.005, 0.3)
    row("element matrices (QM6, host, once per mesh)", None, time.perf_counter() - start)
    h = np.sqrt(mesh.element_areas().mean())
    filt_s = _time_host(lambda: fd.DensityFilter(link.domain, 2.0 * h), 1)
    row("density filter construction (radius 2 h)", None, filt_s)
    reduction = fd.ModalReduction(args.modes, fd.Clamped(link.rims[0]),
                                  interfaces=(fd.Interface(link.rims[1], rigid=True),), solver=fd.LanczosModes())
    body = fd.DesignedBody(model, link.domain, fd.SIMP(), reduction, (link.rims[0], link.rims[1]))
    x = body.initial_design(0.5)
    layout = reduction.layout(mesh)
    youngs, rho = (np.asarray(v) for v in eqx.filter_jit(lambda b, x: b.element_values(x))(body, x))
    unit_k, unit_m = np.asarray(model.unit_stiffness), np.asarray(model.unit_mass)
    k, _ = fd.csc_matrices(mesh, youngs, rho, unit_k, unit_m, layout.removed)
    row("host CSC assembly K_II, M_II (cached pattern)", None,
        _time_host(lambda: fd.csc_matrices(mesh, youngs, rho, unit_k, unit_m, layout.removed), args.runs))
    phi = jnp.asarray(np.random.default_rng(0).normal(size=(mesh.n_dof, args.modes + 3)))
    row("matrix-free K @ Phi", *_time_compiled(lambda b, x, phi: b.model.stiffness(b.element_values(x)[0]) @ phi,
                                               (body, x, phi), args.runs))
    row("modal basis x -> Phi (Lanczos + static modes)", *_time_compiled(lambda b, x: b.modes(x).modes, (body, x), args.runs))
    row("forward x -> body data", *_time_compiled(lambda b, x: b.body_data(x), (body, x), args.runs))
    row("VJP: gradient of a body-data invariant", *_time_compiled(
        lambda b, x: jax.grad(lambda x: _invariant(b, x))(x), (body, x), args.runs))
    frequencies = np.asarray(eqx.filter_jit(lambda b, x: b.frequencies(x))(body, x))

    threads = (f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '(default)')}, "
               f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', '(default)')}")
    lines = [
        "Command: `OPENBLAS_NUM_THREADS=1 flock /tmp/ffr_bench.lock python benchmarks/bench_design_fe.py "
        f"--mesh-size {args.mesh_size} --runs {args.runs} --write`",
        "",
        f"- {machine()}; {threads}",
        f"- mesh: gmsh link with two pin holes (0.2 x 0.05 m, holes r = 8 mm, solid rims 5 mm), "
        f"{mesh.n_elements:,} quadrilaterals, {mesh.n_nodes:,} nodes, {mesh.n_dof:,} dofs, "
        f"{link.domain.n_design:,} design variables; min corner-Jacobian ratio {mesh.jacobian_ratios().min():.2f}",
        f"- element QM6, SIMP x = 0.5, clamped at hole A ({len(link.rims[0])} rim nodes), rigid interface at hole B "
        f"(3 static modes), {args.modes} eigenmodes by LanczosModes; K_II has {k.nnz:,} non-zeros",
        f"- eigenfrequencies [Hz]: {', '.join(f'{f:.1f}' for f in frequencies)}",
        f"- median of {args.runs} runs after a warm-up; peak RSS is the process maximum so far",
        "",
        "| stage | compile [s] | run, median [s] | peak RSS [MB] |",
        "|---|---:|---:|---:|",
    ]
    for stage, compile_s, run_s, peak in rows:
        c = "" if compile_s is None else f"{compile_s:.2f}"
        lines.append(f"| {stage} | {c} | {run_s:.3f} | {peak:,.0f} |")
    forward = next(r[2] for r in rows if r[0].startswith("forward"))
    vjp = next(r[2] for r in rows if r[0].startswith("VJP"))
    lines += ["", f"VJP / forward (same run): {vjp / forward:.2f}."]
    text = "\n".join(lines)
    print(text)
    if args.write:
        write_section("FE stage on unstructured meshes", text)


if __name__ == "__main__":
    main()
