"""The `ffr-jax` command line: `info`, `gradient`, `optimize`, `benchmark`."""

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from ._optimize._cli import add_optimize_parser


def _add_case_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("case", choices=["slider-crank"], help="the scene (the paper's reference case)")
    p.add_argument("--nx", type=int, default=100, help="elements along the rod (default 100)")
    p.add_argument("--ny", type=int, default=6, help="elements across the rod, even (default 6)")
    p.add_argument("--modes", type=int, default=6, help="retained modes (default 6)")
    p.add_argument("--t1", type=float, default=3.0, help="end time in s (default 3)")
    p.add_argument("--value", type=float, default=0.5, help="uniform design density (default 0.5)")


def _make_case(args):
    import ffr_jax as fj

    return fj.cases.slider_crank(nx=args.nx, ny=args.ny, n_modes=args.modes, t1=args.t1)


def _info(args) -> int:
    import jax

    case = _make_case(args)
    x = case.initial_design(args.value)
    t = time.perf_counter()
    data = jax.block_until_ready(case.body_data(x))
    freq = np.asarray(case.frequencies(x))
    elapsed = time.perf_counter() - t
    print(f"slider-crank rod: {case.mesh.nx} x {case.mesh.ny} Q4 elements, {case.n_design} design variables, "
          f"x = {args.value}")
    print("natural frequencies [Hz]: " + ", ".join(f"{f:.4g}" for f in freq))
    print(f"mass {float(data.mass):.6g} kg, centre of mass x {float(data.first_moment[0] / data.mass):.6g} m, "
          f"inertia about A {float(data.inertia):.6g} kg m^2")
    print(f"modal mass diag {np.round(np.diag(np.asarray(data.modal_mass)), 12)}")
    print(f"(FE + modes + body data, compile included: {elapsed:.2f} s)")
    return 0


def _gradient(args) -> int:
    import jax

    import ffr_jax as fj

    case = _make_case(args)
    x = case.initial_design(args.value)
    method = args.method
    if args.method == "fd" and args.fd_step is not None:
        method = fj.FiniteDifferences(step=args.fd_step)
    elif args.method in ("adjoint", "backsolve"):
        defaults = fj.Adjoint() if args.method == "adjoint" else fj.Backsolve()
        rtol = defaults.rtol if args.backward_rtol is None else args.backward_rtol
        atol = defaults.atol if args.backward_atol is None else args.backward_atol
        method = fj.Adjoint(rtol=rtol, atol=atol) if args.method == "adjoint" else fj.Backsolve(rtol=rtol, atol=atol)
    print(f"slider-crank rod: {case.mesh.nx} x {case.mesh.ny} Q4 elements, {case.n_design} design variables, "
          f"x = {args.value}, {case.n_modes} modes, t1 = {case.t1} s; method {args.method}, "
          f"rtol {args.rtol:g}, atol {args.atol:g}")
    fun = jax.jit(lambda x: fj.value_and_grad(case, x, method, rtol=args.rtol, atol=args.atol))
    start = time.perf_counter()
    compiled = fun.lower(x).compile()
    compile_s = time.perf_counter() - start
    runs = []
    for _ in range(2):
        start = time.perf_counter()
        psi, grad = jax.block_until_ready(compiled(x))
        runs.append(time.perf_counter() - start)
    psi, grad = float(psi), np.asarray(grad)
    timings = {"compile_s": compile_s, "first_call_s": runs[0], "compile_and_first_call_s": compile_s + runs[0],
               "second_call_s": runs[1]}

    print(f"psi = {psi:.10e}")
    row, col = np.unravel_index(np.argmax(np.abs(case.design_grid(grad))), (case.mesh.ny, case.mesh.nx - 2))
    print(f"gradient: min {grad.min():.4e}, max {grad.max():.4e}, max |g| {np.abs(grad).max():.4e} "
          f"(element row {row}, column {col + 1}), 2-norm {np.linalg.norm(grad):.4e}")
    print("sign pattern by element row (bottom to top):")
    for row in fj.row_signs(case, grad):
        print(f"  row {row['row']}  y in [{row['y_min']:+.4f}, {row['y_max']:+.4f}] m: "
              f"{row['n_negative']:4d} negative, {row['n_positive']:4d} positive, mean {row['mean']:+.3e}  "
              f"[{row['sign']}]")
    print(f"timings: compile {compile_s:.2f} s, compile + first call {timings['compile_and_first_call_s']:.2f} s, "
          f"second call {runs[1]:.3f} s")

    if args.json is not None:
        record = {
            "psi": psi,
            "grad": grad.tolist(),
            "timings": timings,
            "case": {"name": args.case, "nx": case.mesh.nx, "ny": case.mesh.ny, "modes": case.n_modes,
                     "t1": case.t1, "value": args.value},
            "method": args.method,
            "rtol": args.rtol,
            "atol": args.atol,
            "grid_shape": [case.mesh.ny, case.mesh.nx - 2],
        }
        Path(args.json).write_text(json.dumps(record, indent=1))
        print(f"wrote {args.json}")
    if args.plot is not None:
        figure = fj.plot_gradient(case, grad, title=f"dpsi/dx ({args.method}), {case.mesh.nx} x {case.mesh.ny} rod, "
                                                    f"x = {args.value}, psi = {psi:.6e}")
        figure.savefig(args.plot, dpi=150)
        print(f"wrote {args.plot}")
    return 0


def _add_gradient_parser(sub) -> None:
    from ._api import METHODS

    p = sub.add_parser(
        "gradient",
        help="objective psi and its gradient with respect to all densities",
        description="psi of the case at a uniform design and its design gradient by one sensitivity method: "
                    "a summary with the sign pattern by element row, and compile and run times. "
                    "--json writes {psi, grad (design order), timings, ...}; --plot draws the field over the rod.",
    )
    _add_case_arguments(p)
    p.add_argument("--method", choices=sorted(METHODS), default="adjoint", help="sensitivity method (default adjoint)")
    p.add_argument("--rtol", type=float, default=1e-10, help="forward relative tolerance (default 1e-10)")
    p.add_argument("--atol", type=float, default=1e-12, help="forward absolute tolerance (default 1e-12)")
    p.add_argument("--backward-rtol", type=float, default=None,
                   help="relative tolerance of the backward solve of adjoint / backsolve (default 1e-8)")
    p.add_argument("--backward-atol", type=float, default=None,
                   help="absolute tolerance of the backward solve (default 1e-10; keep it well below |psi|)")
    p.add_argument("--fd-step", type=float, default=None,
                   help="finite-difference step for --method fd (default: ffr_jax.FiniteDifferences's)")
    p.add_argument("--json", metavar="PATH", help="write psi, grad and timings as JSON")
    p.add_argument("--plot", metavar="PATH", help="draw the gradient field over the rod (PNG, PDF, ...)")
    p.set_defaults(func=_gradient)


CACHE_ENV = "FFR_JAX_CACHE_DIR"
NO_CACHE_ENV = "FFR_JAX_NO_CACHE"


def cache_directory() -> Path | None:
    """Where the CLI keeps JAX's persistent compilation cache, or `None` when it is turned off.

    `$FFR_JAX_CACHE_DIR` if set, else `ffr_jax/xla` in the user's cache directory
    (`$XDG_CACHE_HOME` or `~/.cache`); `FFR_JAX_NO_CACHE=1` (or `--no-cache`) turns it off.
    """
    if os.environ.get(NO_CACHE_ENV, "").strip() not in ("", "0"):
        return None
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ffr_jax" / "xla"


def _use_cache(enabled: bool) -> None:
    """Turn on JAX's persistent compilation cache, so that a second run of a command skips compilation."""
    directory = cache_directory() if enabled else None
    if directory is None:
        return
    import jax

    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        print(f"ffr-jax: warning: compilation cache off ({directory}: {err.strerror})", file=sys.stderr)
        return
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="ffr-jax", description=__doc__)
    parser.add_argument("--no-cache", action="store_true",
                        help=f"do not use the persistent compilation cache (also {NO_CACHE_ENV}=1; its directory: "
                             f"${CACHE_ENV} or ~/.cache/ffr_jax/xla)")
    sub = parser.add_subparsers(dest="command", required=True)
    p_info = sub.add_parser("info", help="frequencies, mass and body data of a case's rod")
    _add_case_arguments(p_info)
    p_info.set_defaults(func=_info)
    _add_gradient_parser(sub)
    add_optimize_parser(sub)
    args = parser.parse_args(argv)
    _use_cache(not args.no_cache)
    try:
        return args.func(args)
    except (ValueError, RuntimeError) as err:
        print(f"ffr-jax: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
