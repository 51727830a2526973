"""Solid elements and the FE stage of a solid part (issue 27): accuracy figures and cost against the element count.

Accuracy (host NumPy/SciPy, seconds): the cantilever tip deflection of `tests/test_solid_elements.py`
(L / h = 10, nu = 0, 10n x n x n cells) for H8, H11 and Tet10 against Timoshenko, and the exactness
figure of `tests/test_solid_mesh.py` (one layer of H8 through the reference rod's thickness, nu = 0,
against the Q4 plane-stress rod: in-plane free-free frequencies).

Cost (one run each, the machine's load printed): for box grids of about 10^3, 10^4 and 10^5 H8 or
H11 elements (a free beam-like block, aspect 16:1:1 in cells), the mesh build with its checks, the
element matrices, the first host CSC assembly of K and M (sparsity pattern included), a second
assembly (pattern cached, a design change), and the first 6 elastic free-free modes
(`free_modes_sparse`: SuperLU + ARPACK shift-invert), with the peak resident memory.

    python benchmarks/bench_solid_fe.py                       # accuracy + cost up to 10^5 elements
    python benchmarks/bench_solid_fe.py --sizes 1000 10000    # a quicker cost table
"""

import argparse
import os
import resource
import time

import numpy as np
import scipy.sparse.linalg as spla

import ffr_jax._design as fd
from ffr_jax._design.element import H8, H11, Tet10
from ffr_jax._design.solid_assembly import SolidFEModel, solid_csc_matrices
from ffr_jax._design.solid_mesh import box_grid, hex_to_tet10
from ffr_jax._design.solid_modes import free_modes_sparse


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _tip(mesh, element, length=1.0, h=0.1):
    x = mesh.nodes
    clamp = np.flatnonzero(np.abs(x[:, 0]) < 1e-12)
    removed = tuple(int(d) for d in np.sort(np.concatenate([3 * clamp, 3 * clamp + 1, 3 * clamp + 2])))
    k, _ = solid_csc_matrices(SolidFEModel(mesh, element, 0.0), np.ones(mesh.n_elements), np.ones(mesh.n_elements),
                              removed)
    end = np.abs(x[:, 0] - length) < 1e-12
    weights = np.zeros(mesh.n_nodes)
    edges = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))
    for e in mesh.elements:
        if mesh.cell_type == "hexahedron" and end[e].sum() == 4:
            p = x[e[end[e]]]
            weights[e[end[e]]] += np.ptp(p[:, 1]) * np.ptp(p[:, 2]) / 4
        elif mesh.cell_type == "tetra10" and end[e[:4]].sum() == 3:
            tri = [i for i in range(4) if end[e[i]]]
            p = x[e[tri]]
            mids = [4 + j for j, (a, b) in enumerate(edges) if a in tri and b in tri]
            weights[e[mids]] += 0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) / 3
    f = np.zeros(mesh.n_dof)
    f[1::3] = weights / h**2
    kept = np.setdiff1d(np.arange(mesh.n_dof), removed)
    timoshenko = length**3 / (3 * h**4 / 12) + length / (5 / 6 * 0.5 * h**2)
    return f[kept] @ spla.spsolve(k, f[kept]) / timoshenko - 1


def convergence_table() -> list[str]:
    rows = ["| cells (10n x n x n) | H8 | H11 | Tet10 (6 per cell) |", "|---|---:|---:|---:|"]
    for n in (1, 2, 4):
        grid = box_grid(10 * n, n, n, 1.0, 0.1, 0.1)
        e = (_tip(grid, H8()), _tip(grid, H11()), _tip(hex_to_tet10(grid), Tet10()))
        rows.append(f"| n = {n} ({grid.n_elements} cells) | {e[0]:+.2e} | {e[1]:+.2e} | {e[2]:+.2e} |")
        print(rows[-1], flush=True)
    return rows


def exactness_rows() -> list[str]:
    n, nx, ny = 600, 100, 6
    planar = fd.FEModel(fd.structured_grid(nx, ny, 1.0, 0.06), fd.Q4(), 0.01, 0.0)
    kq, mq = fd.csc_matrices(planar.mesh, np.full(n, 0.5e11), np.full(n, 8750.0), np.asarray(planar.unit_stiffness),
                             np.asarray(planar.unit_mass))
    solid = SolidFEModel(box_grid(nx, ny, 1, 1.0, 0.06, 0.01), H8(), 0.0)
    ks, ms = solid_csc_matrices(solid, np.full(n, 0.5e11), np.full(n, 8750.0))

    def quotients(k, m, count):
        _, v = spla.eigsh(k, count, m, sigma=-1e2, which="LM", tol=0)
        return np.sort(np.einsum("ni,ni->i", v, k @ v) / np.einsum("ni,ni->i", v, m @ v))

    lam_q, lam_s = quotients(kq, mq, 11), quotients(ks, ms, 36)
    rows = ["| in-plane mode | f Q4 [Hz] | f H8 [Hz] (its place in the H8 spectrum) | f_H8 / f_Q4 - 1 |",
            "|---:|---:|---:|---:|"]
    for i in range(3, 11):
        j = int(np.argmin(np.abs(lam_s - lam_q[i])))
        f_q, f_s = np.sqrt(lam_q[i]) / (2 * np.pi), np.sqrt(lam_s[j]) / (2 * np.pi)
        rows.append(f"| {i - 2} | {f_q:.4f} | {f_s:.4f} (elastic mode {j - 5}) | {np.sqrt(lam_s[j] / lam_q[i]) - 1:+.1e} |")
    return rows


def cost_table(sizes, aspect: int = 16, elements=(H8(), H11())) -> list[str]:
    rows = ["| elements | element | dofs | mesh + checks [s] | element matrices [s] | first CSC K, M [s] | "
            "next CSC K, M [s] | 6 free-free modes [s] | f_7 [Hz] | peak RSS [MB] |",
            "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for target in sizes:
        n = max(1, round((target / aspect) ** (1 / 3)))
        for element in elements:
            start = time.perf_counter()
            mesh = box_grid(aspect * n, n, n, aspect * n / 10, n / 10, n / 10)
            t_mesh = time.perf_counter() - start
            start = time.perf_counter()
            model = SolidFEModel(mesh, element, 0.3)
            t_matrices = time.perf_counter() - start
            x = np.full(mesh.n_elements, 0.5)
            youngs, densities = 0.5e11 * x**3, 8750.0 * x
            start = time.perf_counter()
            solid_csc_matrices(model, youngs, densities)
            t_first = time.perf_counter() - start
            start = time.perf_counter()
            solid_csc_matrices(model, youngs * 1.01, densities)
            t_next = time.perf_counter() - start
            start = time.perf_counter()
            lam, _ = free_modes_sparse(model, youngs, densities, 6)
            t_modes = time.perf_counter() - start
            rows.append(f"| {mesh.n_elements:,} | {type(element).__name__} | {mesh.n_dof:,} | {t_mesh:.2f} | "
                        f"{t_matrices:.2f} | {t_first:.2f} | {t_next:.2f} | {t_modes:.2f} | "
                        f"{np.sqrt(lam[0]) / (2 * np.pi):.1f} | {_rss_mb():,.0f} |")
            print(rows[-1], flush=True)
            del model, mesh
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--aspect", type=int, default=16, help="cells along the block per cell across (default 16)")
    parser.add_argument("--elements", nargs="+", default=["H8", "H11"], choices=["H8", "H11"])
    args = parser.parse_args()
    print(f"load average {os.getloadavg()}", flush=True)
    if not args.no_accuracy:
        print("\n".join(exactness_rows()), flush=True)
        convergence_table()
    cost_table(args.sizes, args.aspect, tuple({'H8': H8(), 'H11': H11()}[e] for e in args.elements))
    print(f"load average {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
