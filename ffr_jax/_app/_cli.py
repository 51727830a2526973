"""The `ffr-jax` command line: `info`, `gradient`, `optimize`, `animate`, `export`."""

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import _cli_checks
from .._dynamics._xla_flags import avoid_batched_lapack_deadlock
from .._sensitivity._cached import CACHE_ENV, NO_CACHE_ENV, cache_directory, use_persistent_cache
from ._cli_scenes import SCENES, USER_CASE_HELP, case_name, describe, is_user_case, make_case, scene_settings
from ._cli_io import add_io_parsers
from ._cli_optimize import add_optimize_parser


def _add_case_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("case", type=case_name(), metavar="CASE",
                   help="the scene: " + "; ".join(f"{k}: {v}" for k, v in SCENES.items()) + "; " + USER_CASE_HELP)
    p.add_argument("--nx", type=int, default=None, help="slider-crank: elements along the rod (default 100)")
    p.add_argument("--ny", type=int, default=None, help="slider-crank: elements across the rod, even (default 6)")
    p.add_argument("--mesh-size", type=float, default=None,
                   help="link-four-bar: target element size of the gmsh mesh in m (default 0.004)")
    p.add_argument("--modes", type=int, default=None, help="retained eigenmodes (default 6; link-four-bar 4)")
    p.add_argument("--t1", type=float, default=None, help="end time in s (default 3; link-four-bar 0.3)")
    p.add_argument("--value", type=float, default=0.5, help="uniform design density (default 0.5)")


def _make_case(args):
    settings = scene_settings(args.case, {"nx": args.nx, "ny": args.ny, "mesh_size": args.mesh_size,
                                          "modes": args.modes, "t1": args.t1})
    return make_case(args.case, settings)


def _info(args) -> int:
    import jax

    _cli_checks.case_options(args)
    case = _make_case(args)
    x = case.initial_design(args.value)
    t = time.perf_counter()
    data = jax.block_until_ready(case.body_data(x))
    freq = np.asarray(case.frequencies(x))
    elapsed = time.perf_counter() - t
    print(f"{describe(args.case, case)}, x = {args.value}")
    print("natural frequencies [Hz]: " + ", ".join(f"{f:.4g}" for f in freq))
    inertia = np.asarray(data.inertia)  # planar: J about the frame origin; spatial: the 3 x 3 tensor
    inertia = f"{float(inertia):.6g}" if inertia.ndim == 0 else f"diag {np.array2string(np.diag(inertia), precision=6)}"
    print(f"mass {float(data.mass):.6g} kg, centre of mass x {float(data.first_moment[0] / data.mass):.6g} m, "
          f"inertia about the frame origin {inertia} kg m^2")
    print(f"modal mass diag {np.round(np.diag(np.asarray(data.modal_mass)), 12)}")
    print(f"(FE + modes + body data, compile included: {elapsed:.2f} s)")
    return 0


def _gradient(args) -> int:
    import jax

    from ._gradient_plot import plot_field, plot_gradient, row_signs
    from .._errors import clean_errors
    from .._sensitivity._adjoint import Adjoint
    from .._sensitivity._backsolve import Backsolve
    from .._sensitivity._finite_differences import FiniteDifferences
    from .._api import sensitivity_method
    from .._sensitivity._cached import cache_events, compile_value_and_grad

    if args.atol is None:
        args.atol = scene_settings(args.case, {})["atol"]
    _cli_checks.gradient_options(args)
    if args.plot is not None and args.case == "connecting-rod":
        raise ValueError("--plot draws the gradient over a planar body; for the connecting rod write it with --json "
                         "(design_elements and grad) and draw it with ffr_jax.plot_solid_design or in ParaView.")
    case = _make_case(args)
    x = case.initial_design(args.value)
    method = args.method
    if args.method == "fd" and args.fd_step is not None:
        method = FiniteDifferences(step=args.fd_step)
    elif args.method in ("adjoint", "backsolve"):
        defaults = Adjoint() if args.method == "adjoint" else Backsolve()
        rtol = defaults.rtol if args.backward_rtol is None else args.backward_rtol
        atol = defaults.atol if args.backward_atol is None else args.backward_atol
        method = Adjoint(rtol=rtol, atol=atol) if args.method == "adjoint" else Backsolve(rtol=rtol, atol=atol)
    print(f"{describe(args.case, case)}, x = {args.value}, {case.n_modes} modes, t1 = {case.t1} s; "
          f"method {args.method}, rtol {args.rtol:g}, atol {args.atol:g}")
    # Compiled as programs the persistent cache can keep (a second run loads them instead of compiling).
    events = cache_events()
    directory = None if args.no_cache else cache_directory()
    compiled, info = compile_value_and_grad(case, x, sensitivity_method(method), rtol=args.rtol, atol=args.atol,
                                            max_steps=args.max_steps,
                                            export_dir=None if directory is None else directory / "programs")
    compile_s = info["compile_s"]
    compiled = clean_errors(compiled)  # run-time errors with the package's message
    # One solve gives psi and the gradient; --repeat N times N - 1 more calls of the compiled program.
    runs = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        psi, grad = jax.block_until_ready(compiled(x))
        runs.append(time.perf_counter() - start)
    psi, grad = float(psi), np.asarray(grad)
    cache = {k: v - events[k] for k, v in cache_events().items()}
    if not (np.isfinite(psi) and np.all(np.isfinite(grad))):
        raise RuntimeError(f"psi = {psi} or the gradient is not finite ({np.count_nonzero(~np.isfinite(grad))} "
                           "entries); nothing is written. Tighten --rtol/--atol or report the case.")
    later = float(np.median(runs[1:])) if len(runs) > 1 else None
    timings = {"compile_s": compile_s, "first_call_s": runs[0], "compile_and_first_call_s": compile_s + runs[0],
               "second_call_s": runs[1] if len(runs) > 1 else None, "later_calls_median_s": later, "calls": len(runs),
               "persistent_cache": cache, "traced_program_loaded": info["exported_loaded"]}

    print(f"psi = {psi:.10e}")
    rod = args.case == "slider-crank"
    largest = int(np.argmax(np.abs(grad)))
    if rod:
        row, col = np.unravel_index(largest, (case.mesh.ny, case.mesh.nx - 2))
        where = f"element row {row}, column {col + 1}"
    else:
        element = int(case.design.domain.design_elements[largest])
        centre = (case.design.domain.design_centroids()[largest] if args.case == "connecting-rod"
                  else case.mesh.element_centroids()[element])
        where = f"element {element} at {np.round(centre, 4).tolist()} m"
    print(f"gradient: min {grad.min():.4e}, max {grad.max():.4e}, max |g| {np.abs(grad).max():.4e} "
          f"({where}), 2-norm {np.linalg.norm(grad):.4e}")
    if rod:
        print("sign pattern by element row (bottom to top):")
        for row in row_signs(case, grad):
            print(f"  row {row['row']}  y in [{row['y_min']:+.4f}, {row['y_max']:+.4f}] m: "
                  f"{row['n_negative']:4d} negative, {row['n_positive']:4d} positive, mean {row['mean']:+.3e}  "
                  f"[{row['sign']}]")
    print(f"timings: compile {compile_s:.2f} s, first call {runs[0]:.3f} s (the one solve; a first call also pays the "
          f"compiled program's one-time setup), compile + first call {timings['compile_and_first_call_s']:.2f} s"
          + (f", {len(runs) - 1} later call(s) median {later:.3f} s" if later is not None else
             " (--repeat N times N - 1 more calls)"))
    print(f"compilation cache: scene-gradient program {'loaded' if info['exported_loaded'] else 'traced'}; "
          f"XLA programs: {cache['cache_hits']} loaded, {cache['cache_misses']} compiled")

    if args.json is not None:
        record = {
            "psi": psi,
            "grad": grad.tolist(),
            "timings": timings,
            "case": {"name": args.case, "n_elements": case.mesh.n_elements, "modes": case.n_modes, "t1": case.t1,
                     "value": args.value},
            "method": args.method,
            "rtol": args.rtol,
            "atol": args.atol,
        }
        if rod:
            record["case"].update(nx=case.mesh.nx, ny=case.mesh.ny)
            record["grid_shape"] = [case.mesh.ny, case.mesh.nx - 2]
        else:
            if not is_user_case(args.case):
                record["case"]["mesh_size"] = scene_settings(args.case, {"mesh_size": args.mesh_size})["mesh_size"]
            record["design_elements"] = np.asarray(case.design.domain.design_elements).tolist()
        text = json.dumps(_cli_checks.finite_record(record, f"--json {args.json}"), indent=1, allow_nan=False)
        _cli_checks.written(lambda path: Path(path).write_text(text), args.json, "--json")
        print(f"wrote {args.json}")
    if args.plot is not None:
        if rod:
            figure = plot_gradient(case, grad, title=f"dpsi/dx ({args.method}), {case.mesh.nx} x {case.mesh.ny} "
                                                        f"rod, x = {args.value}, psi = {psi:.6e}")
        else:
            body = "link coupler" if args.case == "link-four-bar" else f"{args.case}, body {case.design_map.names[0]}"
            figure = plot_field(case, grad, signed=True, title=f"dpsi/dx ({args.method}), {body}, "
                                                                  f"x = {args.value}, psi = {psi:.6e}").figure
        _cli_checks.written(lambda path: figure.savefig(path, dpi=150), args.plot, "--plot")
        print(f"wrote {args.plot}")
    return 0


def _add_gradient_parser(sub) -> None:
    from .._api import METHODS

    p = sub.add_parser(
        "gradient",
        help="objective psi and its gradient with respect to all densities",
        description="psi of the case at a uniform design and its design gradient by one sensitivity method: "
                    "a summary with the sign pattern by element row, and compile and run times. "
                    "--json writes {psi, grad (design order), timings, ...}; --plot draws the field over the designed body.",
    )
    _add_case_arguments(p)
    p.add_argument("--method", choices=sorted(METHODS), default="adjoint", help="sensitivity method (default adjoint)")
    p.add_argument("--rtol", type=float, default=1e-10, help="forward relative tolerance (default 1e-10)")
    p.add_argument("--atol", type=float, default=None,
                   help="forward absolute tolerance (default 1e-12; link-four-bar 1e-15)")
    p.add_argument("--backward-rtol", type=float, default=None,
                   help="relative tolerance of the backward solve of adjoint / backsolve (default 1e-8)")
    p.add_argument("--backward-atol", type=float, default=None,
                   help="absolute tolerance of the backward solve (default 1e-10; keep it well below |psi|)")
    p.add_argument("--fd-step", type=float, default=None,
                   help="finite-difference step for --method fd (default: ffr_jax.FiniteDifferences's)")
    p.add_argument("--max-steps", type=int, default=200_000,
                   help="step budget of each solve, as max_steps of ffr_jax.value_and_grad (default 200000); "
                        "a run that uses it up stops with the same error as the API")
    p.add_argument("--repeat", type=int, default=1,
                   help="calls of the compiled gradient to time (default 1: one solve; 2 or more also times calls "
                        "after the first)")
    p.add_argument("--json", metavar="PATH", help="write psi, grad and timings as JSON")
    p.add_argument("--plot", metavar="PATH", help="draw the gradient field over the designed body (PNG, PDF, ...)")
    p.set_defaults(func=_gradient)


def _use_cache(enabled: bool) -> None:
    """Turn on JAX's persistent compilation cache, so that a second run of a command skips compilation."""
    directory = cache_directory() if enabled else None
    if directory is not None:
        use_persistent_cache(directory)


def main(argv=None) -> int:
    avoid_batched_lapack_deadlock()  # before JAX starts its backend (the command batches modal analyses)
    parser = argparse.ArgumentParser(prog="ffr-jax", description=__doc__)
    parser.add_argument("--no-cache", action="store_true",
                        help=f"do not use the persistent compilation cache (also {NO_CACHE_ENV}=1; its directory: "
                             f"${CACHE_ENV} or ~/.cache/ffr_jax)")
    sub = parser.add_subparsers(dest="command", required=True)
    p_info = sub.add_parser("info", help="frequencies, mass and body data of a case's designed body")
    _add_case_arguments(p_info)
    p_info.set_defaults(func=_info)
    _add_gradient_parser(sub)
    add_optimize_parser(sub)
    add_io_parsers(sub)
    args = parser.parse_args(argv)
    _use_cache(not args.no_cache)
    try:
        return args.func(args)
    except (ValueError, RuntimeError) as err:
        from .._errors import package_error

        print(f"ffr-jax: error: {package_error(err) or err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
