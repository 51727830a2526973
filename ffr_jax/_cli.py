"""The `ffr-jax` command line: `info`, `gradient`, `optimize`, `benchmark`."""

import argparse
import sys
import time

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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="ffr-jax", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p_info = sub.add_parser("info", help="frequencies, mass and body data of a case's rod")
    _add_case_arguments(p_info)
    p_info.set_defaults(func=_info)
    add_optimize_parser(sub)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, RuntimeError) as err:
        print(f"ffr-jax: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
