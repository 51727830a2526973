"""Cost of a solid part's design gradient against its number of elements (issue 27: 10^3 to 10^5 solid elements).

The part: the reference rod's geometry (1 m x 0.06 m x 0.01 m) as a structured grid of plain 8-node hexahedra
(`fj.H8`, Poisson's ratio 0.3; one SIMP density per element), held at the node line through the thickness at A
(`x = 0, y = 0`) in x, y, z and at B (`x = L, y = 0`) in y, z (the floating frame of `fj.cases.solid_rod`), markers A
and B those node lines; 6 modes by the sparse `fj.LanczosModes` (shift-invert Lanczos on the host, the derivative by
complement solves); the rod of the spatial slider–crank (`slider_crank(..., spatial=True)`'s mechanism: crank 0.1 m,
ramp to 12 pi rad/s in 2 s, compliance of the rod to t1 = 3 s), design `x = 0.5 + 0.2 sin(1.7 k)`.

Rows for `--elements N [N ...]`, run one after another in one process (the dynamics program compiled once; the
peak memory is the process's so far), each written to `results/solid_scale/rows.json` when done; `--table` prints
the rows as a Markdown table. Per row:
- setup (not per design): mesh and checks, unit element matrices (`SolidFEModel`), the CSC pattern;
- FE stage forward `x -> body data` with its residuals (compiled; SIMP values, host assembly of `K_II`, `M_II`,
  factorisation, Lanczos, body data), split into the modes (the rest) and the body data (timed alone, on random
  modes: its cost depends on shapes only);
  the host assembly alone beside it;
- the FE stage's VJP (compiled): the pullback of the scene gradient's body-data part through that forward (as a
  gradient runs it: one forward, one pullback);
- the dynamics gradient `d psi / d p` (paper's adjoint, rtol 1e-10, atol 1e-12) after compilation (compiled once per
  process; its program does not depend on the number of elements);
- the whole gradient after compilation = FE forward + VJP + dynamics gradient, and the FE stage's share;
- the process's peak resident memory.

    python benchmarks/bench_solid_scale.py --elements 1000 10000 100000   # 125 x 4 x 2, 250 x 10 x 4, 2000 x 10 x 5
    python benchmarks/bench_solid_scale.py --table
"""

import argparse
import json
import os
import pathlib
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj
from ffr_jax._design.solid_designed_body import SolidDesignedBody
from ffr_jax._design.solid_layout import solid_reduction_layout
from ffr_jax._scene._laws import RampLaw
from ffr_jax.cases._spatial_slider_crank import spatial_slider_crank_problem

# 10^5: a slimmer cross-section than 1000 x 20 x 5 (whose run passed 11 GB in the factorisation, above this shared
# machine's share), so that the sparse factor, which grows with the nodes of a cross-section, stays smaller.
GRIDS = {1000: (125, 4, 2), 10000: (250, 10, 4), 100000: (2000, 10, 5)}
LENGTH, HEIGHT, THICKNESS = 1.0, 0.06, 0.01
N_MODES, T1, T_RAMP, SPEED, ECCENTRICITY = 6, 3.0, 2.0, 12 * np.pi, 0.1
RTOL, ATOL = 1e-10, 1e-12
OUT = pathlib.Path(__file__).with_name("results") / "solid_scale"


def block_rod(nx: int, ny: int, nz: int, n_modes: int, modal_solver) -> SolidDesignedBody:
    """The rod as `nx x ny x nz` H8 (module docstring); `ny` even, so that a node line runs along `y = 0`."""
    grid = fj.box_grid(nx, ny, nz, LENGTH, HEIGHT, THICKNESS)
    nodes = grid.nodes - np.array([0.0, HEIGHT / 2, THICKNESS / 2])
    mesh = fj.SolidMesh(nodes, grid.elements)
    on_axis = np.abs(nodes[:, 1]) < 1e-12
    a = tuple(int(n) for n in np.flatnonzero(on_axis & (np.abs(nodes[:, 0]) < 1e-12)))
    b = tuple(int(n) for n in np.flatnonzero(on_axis & (np.abs(nodes[:, 0] - LENGTH) < 1e-12)))
    fixed = tuple(sorted([3 * n + d for n in a for d in range(3)] + [3 * n + d for n in b for d in (1, 2)]))
    model = fj.SolidFEModel(mesh, fj.H8(), 0.3)
    return SolidDesignedBody(model, fj.SolidDesignDomain(mesh), fj.SIMP(), n_modes, fixed, (a, b), modal_solver)


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def clock(fn, *args):
    start = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    return time.perf_counter() - start, out


def row(n_elements: int, dynamics: bool = True) -> dict:
    nx, ny, nz = GRIDS[n_elements]
    out = {"elements": n_elements, "grid": f"{nx} x {ny} x {nz}", "load_start": os.getloadavg()[0]}
    cpu_start, wall_start = time.process_time(), time.perf_counter()
    t, body = clock(lambda: block_rod(nx, ny, nz, N_MODES, fj.LanczosModes()))
    out.update(dofs=body.mesh.n_dof, setup_s=t)
    print(f"{n_elements} H8 ({out['grid']}), {body.mesh.n_dof} dof: mesh + element matrices {t:.1f} s", flush=True)
    x = body.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(body.n_design, dtype=float))
    youngs, densities = (np.asarray(v) for v in body.element_values(x))
    layout = solid_reduction_layout(body.mesh, body.fixed_dofs)
    unit_k, unit_m = np.asarray(body.model.unit_stiffness), np.asarray(body.model.unit_mass)
    out["pattern_s"], _ = clock(lambda: layout.csc_matrices(youngs, densities, unit_k, unit_m))
    out["assembly_s"], _ = clock(lambda: layout.csc_matrices(youngs, densities, unit_k, unit_m))
    del youngs, densities, unit_k, unit_m
    print(f"  CSC pattern (once per mesh) {out['pattern_s']:.1f} s, assembly of K_II, M_II {out['assembly_s']:.2f} s, "
          f"peak {peak_mb():.0f} MB", flush=True)

    # The forward with its residuals, then the pullback: one forward, as a gradient runs it (a second forward would
    # also be free to return the modes with other signs, which the cotangent of the first would not match).
    start = time.perf_counter()
    forward = jax.jit(lambda body, x: jax.vjp(body.body_data, x)).lower(body, x).compile()
    out["forward_compile_s"] = time.perf_counter() - start
    out["forward_s"], (data, pullback) = clock(forward, body, x)
    lam = np.diag(np.asarray(data.modal_stiffness))
    out["frequencies_hz"] = list(np.sqrt(lam) / (2 * np.pi))
    print(f"  FE forward: compile {out['forward_compile_s']:.1f} s, run {out['forward_s']:.1f} s; f = "
          f"{np.round(out['frequencies_hz'], 1)} Hz, peak {peak_mb():.0f} MB", flush=True)
    modes = jnp.asarray(np.random.default_rng(0).standard_normal((body.mesh.n_dof, N_MODES)))  # its cost: shapes only
    body_data_only = jax.jit(lambda body, x, modes: fj.solid_body_data(
        body.mesh.nodes, *body.matrices(x), modes, body.markers, elements=body.mesh.elements))
    body_data_only = body_data_only.lower(body, x, modes).compile()
    out["body_data_s"], _ = clock(body_data_only, body, x, modes)
    del modes
    out["modes_s"] = out["forward_s"] - out["body_data_s"]

    if dynamics:
        law = RampLaw(t_ramp=T_RAMP, angle_at_ramp=SPEED * T_RAMP / 2, speed=SPEED)
        problem = spatial_slider_crank_problem(None, ECCENTRICITY, law, T1, rod_data=data)
        start = time.perf_counter()
        psi, grad = fj.value_and_grad(problem, method="adjoint", rtol=RTOL, atol=ATOL)
        out["dynamics_first_s"] = time.perf_counter() - start
        out["dynamics_s"], (psi, grad) = clock(lambda: fj.value_and_grad(problem, method="adjoint", rtol=RTOL,
                                                                          atol=ATOL))
        out["psi"] = float(psi)
        cotangent = grad.scene.bodies[0].data
        print(f"  dynamics gradient: first call (compile or load) {out['dynamics_first_s']:.1f} s, run "
              f"{out['dynamics_s']:.2f} s, psi = {float(psi):.6e}", flush=True)
    else:  # the FE stage alone: a cotangent of the body data's shape (the VJP's cost does not depend on its values)
        cotangent = jax.tree_util.tree_map(lambda a: jnp.asarray(np.random.default_rng(1).standard_normal(a.shape)),
                                           data)
        out["dynamics_s"] = float("nan")

    start = time.perf_counter()
    backward = jax.jit(lambda pullback, cotangent: pullback(cotangent)[0]).lower(pullback, cotangent).compile()
    out["vjp_compile_s"] = time.perf_counter() - start
    out["vjp_s"], g = clock(backward, pullback, cotangent)
    out["grad_max_abs"] = float(jnp.max(jnp.abs(g)))
    out["fe_s"] = out["forward_s"] + out["vjp_s"]
    out["gradient_s"] = out["fe_s"] + out["dynamics_s"]
    out["fe_share"] = out["fe_s"] / out["gradient_s"]
    out["peak_mb"] = peak_mb()
    out["load_end"] = os.getloadavg()[0]
    out["cpu_share"] = (time.process_time() - cpu_start) / (time.perf_counter() - wall_start)  # cores used on average
    print(f"  FE VJP: compile {out['vjp_compile_s']:.1f} s, run {out['vjp_s']:.1f} s; whole gradient "
          f"{out['gradient_s']:.1f} s, FE share {out['fe_share']:.1%}, peak {out['peak_mb']:.0f} MB", flush=True)
    return out


def table(rows: list) -> str:
    lines = ["| elements (H8) | grid | dofs | setup [s] | assembly [s] | FE forward [s] (modes / body data) "
             "| FE VJP [s] | dynamics gradient [s] | whole gradient [s] | FE share | peak RSS [MB] | load |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in sorted(rows, key=lambda r: r["elements"]):
        lines.append(f"| {r['elements']:,} | {r['grid']} | {r['dofs']:,} | {r['setup_s']:.1f} | {r['assembly_s']:.2f} "
                     f"| {r['forward_s']:.1f} ({r['modes_s']:.1f} / {r['body_data_s']:.2f}) | {r['vjp_s']:.1f} "
                     f"| {r['dynamics_s']:.2f} "
                     f"| {r['gradient_s']:.1f} | {r['fe_share']:.0%} | {r['peak_mb']:,.0f} "
                     f"| {r['load_start']:.1f}-{r['load_end']:.1f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--elements", type=int, nargs="+", choices=sorted(GRIDS))
    parser.add_argument("--table", action="store_true")
    parser.add_argument("--fe-only", action="store_true", help="skip the dynamics (FE stage and its VJP only)")
    args = parser.parse_args()
    path = OUT / "rows.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    for n in args.elements or ():
        result = row(n, dynamics=not args.fe_only)
        key = (n, args.fe_only)
        rows = [r for r in rows if (r["elements"], r.get("fe_only", False)) != key]
        rows.append(dict(result, fe_only=args.fe_only))
        OUT.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(rows, indent=1))
    if args.table or not args.elements:
        print(table(rows))
