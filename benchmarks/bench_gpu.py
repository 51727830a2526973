"""The reference case on whatever JAX platform this process has (a GPU, or the CPU), single and batched.

What it measures, in one process, for one platform:
- the paper's adjoint gradient of `fj.cases.slider_crank()` at x = 0.5 (`method="adjoint"`): the first call
  (trace + compile + run, empty caches) and the median of three later calls; psi and the gradient against a
  reference file computed on another machine (the CPU of the development machine, `reference_numbers.py`);
- a batch of B designs (x = 0.5 + small distinct perturbations) through `jax.vmap` of the same call: first call
  and the median of two later calls, per batch size, and the batch's throughput against B single calls.

Usage (one platform per process; run it twice on a GPU machine for the CPU comparison):
    python benchmarks/bench_gpu.py --reference ref.npz --batches 1 8 32 --out gpu.json
    JAX_PLATFORMS=cpu python benchmarks/bench_gpu.py --reference ref.npz --batches 1 8 --out cpu.json
Each result is appended to the JSON file as soon as it is measured (a run stopped at its limit keeps what it had).
"""

import argparse
import json
import os
import statistics
import time

import numpy as np


def _write(path, record):
    records = json.load(open(path)) if os.path.exists(path) else []
    records.append(record)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(records, f, indent=1)
    os.replace(tmp, path)
    print(json.dumps(record), flush=True)


def _timed(fn, *args):
    start = time.perf_counter()
    out = fn(*args)
    import jax

    jax.block_until_ready(out)
    return out, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", help="npz of reference_numbers.py (psi, grad) to compare against")
    parser.add_argument("--case", default="reference", choices=["reference", "small"])
    parser.add_argument("--batches", type=int, nargs="*", default=[])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--objective-only", action="store_true", help="time fj.objective (the forward run) only")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()

    import logging

    import jax

    import ffr_jax as fj

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")  # compile messages

    device = jax.devices()[0]
    base = {"platform": device.platform, "device": str(getattr(device, "device_kind", device)),
            "jax": jax.__version__, "case": args.case}
    case = fj.cases.slider_crank() if args.case == "reference" else fj.cases.slider_crank(4, 2, 2, 0.1)
    x = case.initial_design(0.5)

    if args.objective_only:
        psi, first = _timed(lambda x: fj.objective(case, x), x)
        later = [_timed(lambda x: fj.objective(case, x), x)[1] for _ in range(args.repeats)]
        _write(args.out, dict(base, what="objective", first_s=first, later_median_s=statistics.median(later),
                              psi=float(psi)))
        return

    def single(x):
        return fj.value_and_grad(case, x, method="adjoint")

    (psi, grad), first = _timed(single, x)
    later = [_timed(single, x)[1] for _ in range(args.repeats)]
    record = dict(base, what="single", first_s=first, later_median_s=statistics.median(later), later_s=later,
                  psi=float(psi), max_abs_grad=float(np.max(np.abs(np.asarray(grad)))))
    if args.reference:
        ref = np.load(args.reference)
        record["psi_rel_to_reference"] = abs(float(psi) - float(ref["psi"])) / abs(float(ref["psi"]))
        record["grad_rel_to_reference"] = float(np.max(np.abs(np.asarray(grad) - ref["grad"])) /
                                                np.max(np.abs(ref["grad"])))
    _write(args.out, record)

    batched = jax.vmap(single)
    rng = np.random.default_rng(0)
    for b in args.batches:
        xs = np.clip(0.5 + 0.05 * rng.standard_normal((b, case.n_design)), 0.1, 1.0)
        (psis, grads), first = _timed(batched, xs)
        later = [_timed(batched, xs)[1] for _ in range(2)]
        # the batch's first member against the same design alone (a batched solve steps all members together,
        # with the steps of the hardest member; its result is the member's own to the solver tolerance)
        (psi0, grad0), _ = _timed(single, xs[0])
        _write(args.out, dict(base, what="batch", batch=b, first_s=first, later_median_s=statistics.median(later),
                              per_design_s=statistics.median(later) / b,
                              psi0_rel_to_single=abs(float(psis[0]) - float(psi0)) / abs(float(psi0)),
                              grad0_rel_to_single=float(np.max(np.abs(np.asarray(grads[0]) - np.asarray(grad0))) /
                                                        np.max(np.abs(np.asarray(grad0))))))


if __name__ == "__main__":
    main()
