"""Accuracy of the elements: a slender cantilever (bending locking) and a plate with a hole (convergence).

1. The 10 m spin-up beam of Simo and Vu-Quoc (E = 7e10 Pa, rho = 2766.67 kg/m^3, A = 4e-4 m^2,
   I = 2e-7 m^4, i.e. a rectangle 77.5 mm x 5.16 mm), clamped at x = 0, nu = 0, meshed nx x 2:
   first frequency against Euler–Bernoulli, `omega_1 = 1.8751^2 sqrt(E I / (rho A)) / L^2`.
2. A steel square plate 1 m x 1 m x 10 mm with a central hole r = 0.2 m, outer edges clamped,
   in-plane: first frequency on nested O-grids n = 4..64 (4 n^2 elements), the observed order and
   the Richardson limit from each pair of refinements, Q4 and QM6.

Host eigen-solutions (LanczosModes' solver, no compilation). Writes the section "Elements:
bending of a slender beam, plate with a hole" of `benchmarks/RESULTS.md` with `--write`.

Usage: `python benchmarks/bench_elements.py [--write]`
"""

import argparse
import os
import sys

import jax.numpy as jnp
import numpy as np

import ffr_jax._design as fd

sys.path.insert(0, os.path.dirname(__file__))
from _results import machine, write_section  # noqa: E402

BEAM_L, BEAM_E, BEAM_RHO, BEAM_A, BEAM_I = 10.0, 7e10, 2766.67, 4e-4, 2e-7
BEAM_H = np.sqrt(12 * BEAM_I / BEAM_A)
EULER_BERNOULLI = 1.875104068711961**2 * np.sqrt(BEAM_E * BEAM_I / (BEAM_RHO * BEAM_A)) / BEAM_L**2


def _first_eigenvalue(mesh, element, thickness, poisson, youngs, density, held_nodes):
    model = fd.FEModel(mesh, element, thickness, poisson)
    layout = fd.ModalReduction(1, fd.Clamped(held_nodes)).layout(mesh)
    ones = jnp.ones(mesh.n_elements)
    lam, _ = fd.LanczosModes().solve(model, youngs * ones, density * ones, layout, 2)
    return float(lam[0])


def beam_table():
    lines = [f"Cantilever, Euler–Bernoulli omega_1 = {EULER_BERNOULLI:.4f} rad/s "
             f"(h = {BEAM_H * 1e3:.1f} mm, b = {BEAM_A / BEAM_H * 1e3:.2f} mm, nu = 0).", "",
             "| mesh | element aspect dx / (h/2) | Q4 omega_1 [rad/s] | Q4 error | QM6 omega_1 [rad/s] | QM6 error |",
             "|---|---:|---:|---:|---:|---:|"]
    for nx in (100, 200, 400):
        mesh = fd.structured_grid(nx, 2, BEAM_L, BEAM_H)
        w = [np.sqrt(_first_eigenvalue(mesh, e, BEAM_A / BEAM_H, 0.0, BEAM_E, BEAM_RHO, range(3)))
             for e in (fd.Q4(), fd.QM6())]
        lines.append(f"| {nx} x 2 | {BEAM_L / nx / (BEAM_H / 2):.2f} | {w[0]:.4f} | {w[0] / EULER_BERNOULLI - 1:+.2%} "
                     f"| {w[1]:.5f} | {w[1] / EULER_BERNOULLI - 1:+.1e} |")
    return lines


def plate_table():
    lines = ["Plate with a hole (clamped outer edges, in-plane), first frequency [Hz]; order p = "
             "log2((f_h - f_h/2) / (f_h/2 - f_h/4)), limit f_h/4 + (f_h/4 - f_h/2) / (2^p - 1).", "",
             "| n (elements) | Q4 f_1 | Q4 order | Q4 limit | QM6 f_1 | QM6 order | QM6 limit |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    ns = (4, 8, 16, 32, 64)
    f = {}
    for element in (fd.Q4(), fd.QM6()):
        values = []
        for n in ns:
            plate = fd.plate_with_hole(1.0, 0.2, n)
            lam = _first_eigenvalue(plate.mesh, element, 0.01, 0.3, 2.1e11, 7850.0, plate.outer_nodes)
            values.append(np.sqrt(lam) / (2 * np.pi))
        f[type(element).__name__] = np.array(values)
    for i, n in enumerate(ns):
        cells = []
        for name in ("Q4", "QM6"):
            v = f[name]
            if i >= 2:
                p = np.log2((v[i - 2] - v[i - 1]) / (v[i - 1] - v[i]))
                cells += [f"{v[i]:.3f}", f"{p:.3f}", f"{v[i] + (v[i] - v[i - 1]) / (2**p - 1):.3f}"]
            else:
                cells += [f"{v[i]:.3f}", "", ""]
        lines.append(f"| {n} ({4 * n * n}) | " + " | ".join(cells) + " |")
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    lines = ["Command: `python benchmarks/bench_elements.py --write` (accuracy only; no timings)", "",
             f"- {machine()}", ""] + beam_table() + [""] + plate_table()
    text = "\n".join(lines)
    print(text)
    if args.write:
        write_section("Elements: bending of a slender beam, plate with a hole", text)


if __name__ == "__main__":
    main()
