"""psi and the adjoint gradient of the reference case, written to a file, and two such files compared.

Issue 29 asks that a restructuring leave the reference numbers unchanged to 1e-12. The same computation
(`fj.cases.slider_crank()`, x = 0.5, `fj.value_and_grad(case, x, method="adjoint")`: the paper's adjoint
with the paper's tolerances) is run by the code before and after, each in a fresh process, and the two
results compared entry by entry (relative to max|g|).

Usage:
    python benchmarks/reference_numbers.py --out after.npz           # with this checkout
    git worktree add /tmp/before <commit>
    PYTHONPATH=/tmp/before python benchmarks/reference_numbers.py --out before.npz
    python benchmarks/reference_numbers.py --compare before.npz after.npz
"""

import argparse
import time

import numpy as np


def compute(out: str) -> None:
    import ffr_jax as fj

    case = fj.cases.slider_crank()
    x = case.initial_design(0.5)
    start = time.perf_counter()
    psi, grad = fj.value_and_grad(case, x, method="adjoint")
    np.savez(out, psi=float(psi), grad=np.asarray(grad), source=fj.__file__, wall=time.perf_counter() - start)
    print(f"psi = {float(psi):.15e}, max|g| = {float(np.max(np.abs(grad))):.6e} ({fj.__file__}) -> {out}")


def compare(a: str, b: str) -> None:
    before, after = np.load(a), np.load(b)
    psi = abs(float(after["psi"]) - float(before["psi"])) / abs(float(before["psi"]))
    grad = float(np.max(np.abs(after["grad"] - before["grad"])) / np.max(np.abs(before["grad"])))
    print(f"psi {float(before['psi']):.15e} -> {float(after['psi']):.15e}: relative {psi:.1e}; "
          f"gradient max-norm relative {grad:.1e}; {'unchanged to 1e-12' if max(psi, grad) <= 1e-12 else 'CHANGED'}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out")
    parser.add_argument("--compare", nargs=2)
    args = parser.parse_args()
    compare(*args.compare) if args.compare else compute(args.out)
