"""The reference case's numbers after the problem type and the design map (issues 12 and 13): unchanged.

Recomputes psi and the gradient of the reference case (`fj.cases.slider_crank()`: 100 x 6 rod, 6 modes,
t1 = 3 s, x = 0.5) with the settings of `bench_gradient.py` (forward rtol 1e-10 / atol 1e-12, adjoint
backward 1e-8 / 1e-10; autodiff through the same forward solve) and compares them with the values that
`bench_gradient.py` stored in `benchmarks/results/gradient.json` before either change (the commit it
names). The stored and the new computation are independent runs of code that was restructured in
between (the FE stage, modal reduction, body data, the case type and the objective all moved), so the
agreement measures the restructuring, not a repeated call.

What "unchanged" can mean: both runs integrate the same equations with the same solver and step
controller; a different order of floating-point operations (e.g. assembly by element instead of by
row) perturbs every step by round-off, which the adaptive controller may turn into a slightly different
step sequence, so psi agrees to about the solve's tolerance times the error growth (rtol 1e-10:
allowed 1e-9 relative) and the gradient to the backward tolerance (1e-8: allowed 1e-7 relative,
max-norm).

Usage: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/check_reference_unchanged.py`.
Writes the section "Reference case unchanged (issues 12, 13)" of benchmarks/RESULTS.md.
"""

import json
import pathlib
import subprocess
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _results import machine, write_section  # noqa: E402

PSI_RTOL = 1e-9
GRAD_RTOL = 1e-7


def _relative(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def main() -> None:
    stored = json.loads((pathlib.Path(__file__).parent / "results" / "gradient.json").read_text())
    case = fj.cases.slider_crank()
    x = case.initial_design(0.5)
    tol = dict(rtol=1e-10, atol=1e-12)
    rows = []
    for name, method in (("adjoint", fj.Adjoint(rtol=1e-8, atol=1e-10)), ("autodiff", "autodiff")):
        start = time.perf_counter()
        psi, grad = jax.block_until_ready(fj.value_and_grad(case, x, method, **tol))
        seconds = time.perf_counter() - start
        ref = jnp.asarray(stored[f"grad_{name}"])
        rows.append((name, float(psi), _relative(psi, stored["psi"]), _relative(grad, ref), seconds))
        print(rows[-1], flush=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    ok = all(r[2] <= PSI_RTOL and r[3] <= GRAD_RTOL for r in rows)
    lines = [
        "Command: `PYTHONPATH=$PWD flock /tmp/ffr_bench.lock python benchmarks/check_reference_unchanged.py` "
        f"at commit {head}.",
        f"Machine: {machine()}.",
        "",
        "The reference case (`fj.cases.slider_crank()`, x = 0.5, forward rtol 1e-10 / atol 1e-12, adjoint "
        "backward 1e-8 / 1e-10) recomputed after the problem type (issue 12) and the design map (issue 13), "
        "against `benchmarks/results/gradient.json` written by `bench_gradient.py` before both "
        f"(psi = {stored['psi']:.10e}). Allowed (see the script's docstring): psi {PSI_RTOL:g} relative, "
        f"gradient {GRAD_RTOL:g} relative in the max-norm.",
        "",
        "| method | psi | psi vs stored, relative | gradient vs stored, max-norm relative | wall (compile + run) [s] |",
        "|---|---:|---:|---:|---:|",
    ]
    lines += [f"| {n} | {p:.10e} | {dp:.1e} | {dg:.1e} | {s:.1f} |" for n, p, dp, dg, s in rows]
    lines += ["", f"Result: {'unchanged within the allowed differences' if ok else 'CHANGED: see the table'}."]
    write_section("Reference case unchanged (issues 12, 13)", "\n".join(lines))
    if not ok:
        raise SystemExit("the reference case's numbers moved")


if __name__ == "__main__":
    main()
