"""psi and the adjoint gradient of the rod cases, recorded once and compared across code versions.

Issue 13 (phase 2) replaced the rod's FE, modal and body-data modules by the design subpackage and
a `DesignMap`; the reference numbers must not move. `--record FILE` stores psi and the adjoint
gradient of a set of cases (JSON); `--compare FILE` recomputes them with the code on `PYTHONPATH`
and prints the relative differences (`--write` puts the table into RESULTS.md). Only the public
API is used (`fj.cases.*`, `fj.value_and_grad`), so the same script runs on the old and the new code.
`--unstructured` (new code only) also runs the reference case with its rod read as an
unstructured mesh (nodes and elements shuffled, node lists rotated, written and read through
meshio) and compares psi and the gradient with the structured rod's.

```
PYTHONPATH=$PWD python benchmarks/bench_design_map.py --record benchmarks/results/design_map_before.json
PYTHONPATH=$PWD python benchmarks/bench_design_map.py --compare benchmarks/results/design_map_before.json --unstructured --write
```
"""

import argparse
import json
import pathlib
import sys
import time

import jax
import numpy as np

import ffr_jax as fj


def _cases(reference: bool):
    """`(name, case factory)`: small members of every rod family, and the reference case."""
    out = [
        ("slider_crank 12x2, 4 modes, t1 0.2", lambda: fj.cases.slider_crank(12, 2, 4, 0.2)),
        ("four_bar 12x2, 3 modes, t1 0.2", lambda: fj.cases.four_bar(12, 2, 3, 0.2)),
        ("flexible_pendulum 12x2, 3 modes, t1 0.2", lambda: fj.cases.flexible_pendulum(12, 2, 3, 0.2)),
        ("spinning_beam 12x2, 3 modes, t1 0.1", lambda: fj.cases.spinning_beam(12, 2, 3, 0.1)),
    ]
    if reference:
        out.append(("slider_crank reference 100x6, 6 modes, t1 3", lambda: fj.cases.slider_crank()))
    return out


def _designs(case):
    """A uniform design (0.5) and a random one in [0.2, 0.95] (seed 0)."""
    rng = np.random.default_rng(0)
    return {"x = 0.5": np.asarray(case.initial_design(0.5)), "random": rng.uniform(0.2, 0.95, case.n_design)}


def run(reference: bool) -> dict:
    out = {}
    for name, make in _cases(reference):
        case = make()
        for label, x in _designs(case).items():
            if "reference" in name and label == "random":
                continue
            start = time.perf_counter()
            psi, grad = jax.block_until_ready(fj.value_and_grad(case, x))
            print(f"{name}, {label}: psi {float(psi):.12e}, max|grad| {np.abs(grad).max():.4e} "
                  f"({time.perf_counter() - start:.1f} s with compile)", flush=True)
            out[f"{name} | {label}"] = {"psi": float(psi), "grad": np.asarray(grad).tolist()}
    return out


def unstructured_reference(structured: dict) -> tuple[float, float]:
    """`(relative difference of psi, of the gradient)`: the reference case with its rod as an unstructured mesh."""
    import tempfile

    import jax.numpy as jnp

    case = fj.cases.slider_crank()
    rod = case.design
    mesh, domain = rod.mesh, rod.domain
    rng = np.random.default_rng(1)
    node_of, element_of = rng.permutation(mesh.n_nodes), rng.permutation(mesh.n_elements)
    new_index = np.argsort(node_of)
    shift = rng.integers(0, 4, mesh.n_elements)
    rotated = np.take_along_axis(mesh.elements[element_of], (np.arange(4) + shift[:, None]) % 4, axis=1)
    path = pathlib.Path(tempfile.mkdtemp()) / "rod.vtu"
    fj.write_mesh(str(path), fj.QuadMesh(mesh.nodes[node_of], new_index[rotated]))
    read = fj.read_mesh(str(path))
    shuffled = fj.DesignDomain(read, domain.role_array()[element_of])
    design_index = np.full(mesh.n_elements, -1)
    design_index[np.asarray(domain.design_elements)] = np.arange(domain.n_design)
    design_of = design_index[element_of[np.asarray(shuffled.design_elements)]]
    a, b = (int(new_index[n]) for n in rod.markers)
    body = fj.DesignedBody(fj.FEModel(read, rod.model.element, rod.model.thickness, rod.model.poisson), shuffled,
                           rod.material, fj.ModalReduction(rod.n_modes, fj.HingedHinged(a, b)), (a, b))
    other = fj.cases.slider_crank(rod=body)
    x = np.asarray(case.initial_design(0.5))
    psi, grad = jax.block_until_ready(fj.value_and_grad(other, jnp.asarray(x[design_of])))
    ref_psi, ref_grad = structured["psi"], np.asarray(structured["grad"])
    print(f"unstructured reference: psi {float(psi):.12e}", flush=True)
    return (abs(float(psi) - ref_psi) / abs(ref_psi),
            float(np.abs(np.asarray(grad) - ref_grad[design_of]).max() / np.abs(ref_grad).max()))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--record", metavar="FILE")
    p.add_argument("--compare", metavar="FILE")
    p.add_argument("--no-reference", action="store_true", help="skip the 100 x 6 reference case")
    p.add_argument("--unstructured", action="store_true",
                   help="also the reference case with its rod read as an unstructured mesh (new code only)")
    p.add_argument("--write", action="store_true", help="write the comparison into RESULTS.md")
    args = p.parse_args(argv)
    now = run(not args.no_reference)
    unstructured = None
    if args.unstructured:
        unstructured = unstructured_reference(now["slider_crank reference 100x6, 6 modes, t1 3 | x = 0.5"])
        print(f"unstructured vs structured reference: psi {unstructured[0]:.1e}, gradient {unstructured[1]:.1e}")
    if args.record:
        pathlib.Path(args.record).write_text(json.dumps(now))
        print(f"wrote {args.record}")
    if args.compare:
        before = json.loads(pathlib.Path(args.compare).read_text())
        rows = ["| case, design | psi before | rel. diff. psi | max abs. diff. grad / max abs. grad |",
                "|---|---|---|---|"]
        worst = 0.0
        for key, new in now.items():
            if key not in before:
                continue
            old = before[key]
            d_psi = abs(new["psi"] - old["psi"]) / abs(old["psi"])
            g_old, g_new = np.asarray(old["grad"]), np.asarray(new["grad"])
            d_grad = np.abs(g_new - g_old).max() / np.abs(g_old).max()
            worst = max(worst, d_psi, d_grad)
            rows.append(f"| {key} | {old['psi']:.12e} | {d_psi:.1e} | {d_grad:.1e} |")
        table = "\n".join(rows)
        print(table)
        print(f"largest relative difference {worst:.1e}")
        if args.write:
            sys.path.insert(0, str(pathlib.Path(__file__).parent))
            from _results import machine, write_section

            write_section("Rod cases before and after the design map (bench_design_map.py)", (
                "psi and the adjoint gradient (default tolerances: forward rtol 1e-10 / atol 1e-12, backward "
                "1e-8 / 1e-10) of the rod cases, computed with the old FE modules (commit 084a2ae, "
                "`RodDesignMap`) and with the design map on `ffr_jax._design` (issue 13, phase 2). Differences "
                "are relative to psi and to max |grad|.\n\n"
                f"```\nPYTHONPATH=$PWD python benchmarks/bench_design_map.py --compare {args.compare} --write\n```\n\n"
                f"{table}\n\nLargest relative difference: {worst:.1e}. The rods' body data agree to 1e-12 "
                "(tests/test_design_invariant.py); psi and the gradient move by the solves' tolerance-level changes "
                "of the accepted steps."
                + ("" if unstructured is None else
                   f"\n\n**The reference rod read as an unstructured mesh** (nodes and elements shuffled, node lists "
                   f"rotated, written and read through meshio; `--unstructured`): psi differs from the structured "
                   f"rod's by {unstructured[0]:.1e} (relative), the adjoint gradient by {unstructured[1]:.1e} of "
                   f"max |grad| (design variables matched), at the default tolerances.")
                + f"\n\nMachine: {machine()}."
            ))
    return 0


if __name__ == "__main__":
    sys.exit(main())
