"""The `ffr-jax animate` and `ffr-jax export` subcommands: an optimised design made visible."""

import argparse
import functools
import json
from pathlib import Path

import numpy as np

from ._cli_scenes import USER_CASE_HELP, case_name, is_user_case, load_user_case

_CASE_DEFAULTS = {"nx": 100, "ny": 6, "modes": 6, "t1": 3.0}


@functools.cache
def slider_crank_case(nx: int, ny: int, modes: int, t1: float):
    """The slider–crank of the commands, built once per process for each setting.

    A case is an immutable pytree; sharing one object between commands run in one process (tests,
    notebooks) lets the compiled programs that take it (the animation's motion, the modal analysis)
    be reused instead of traced again.
    """
    from .. import cases

    return cases.slider_crank(nx=nx, ny=ny, n_modes=modes, t1=t1)


def _add_design_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("case", type=case_name(), metavar="CASE",
                   help="slider-crank (the paper's reference case), " + USER_CASE_HELP)
    p.add_argument("--design", metavar="NPZ",
                   help="design.npz of `ffr-jax optimize` (its physical densities x_phys and its case settings)")
    p.add_argument("--value", type=float, default=None,
                   help="a uniform design x = VALUE instead of --design (default 0.5 when no design is given)")
    p.add_argument("--nx", type=int, help="elements along the rod (default: the design's, else 100)")
    p.add_argument("--ny", type=int, help="elements across the rod (default: the design's, else 6)")
    p.add_argument("--modes", type=int, help="retained modes (default: the design's, else 6)")
    p.add_argument("--t1", type=float, help="end time in s (default: the design's run, else 3)")


def _case_and_design(args: argparse.Namespace):
    """The case (settings: defaults < the design's run < options; a user's case: its function's) and the
    physical densities."""
    user = is_user_case(args.case)
    if not user and args.case != "slider-crank":
        raise ValueError(f"animate and export take slider-crank or a user's case FILE.py:FUNCTION, not {args.case}.")
    given = [f"--{key}" for key in _CASE_DEFAULTS if getattr(args, key) is not None]
    if user and given:
        raise ValueError(f"{', '.join(given)}: not options of a user's case ({args.case} sets its mesh, modes and "
                         "times itself).")
    settings = dict(_CASE_DEFAULTS)
    x_phys = None
    if args.design is not None:
        if args.value is not None:
            raise ValueError("Give --design or --value, not both.")
        path = Path(args.design)
        if not path.is_file():
            raise ValueError(f"No design file {path}; pass the design.npz written by `ffr-jax optimize`.")
        try:
            stored = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as err:  # numpy's own text advises allow_pickle: not ours to give
            raise ValueError(f"{path} is not a design file ({type(err).__name__}); pass the design.npz written by "
                             "`ffr-jax optimize`.") from None
        if not hasattr(stored, "files"):
            raise ValueError(f"{path} is a single array, not a design file; pass the design.npz written by "
                             "`ffr-jax optimize`.")
        with stored:
            if "x_phys" not in stored.files:
                raise ValueError(f"{path} holds no physical densities (x_phys); pass the design.npz written by "
                                 "`ffr-jax optimize`.")
            x_phys = np.asarray(stored["x_phys"], dtype=float)
            if "config" in stored.files and not user:
                config = json.loads(str(stored["config"]))
                settings.update({key: config[key] for key in settings if key in config})
    settings.update({key: getattr(args, key) for key in settings if getattr(args, key) is not None})
    if user:
        case = load_user_case(args.case)
    else:
        case = slider_crank_case(int(settings["nx"]), int(settings["ny"]), int(settings["modes"]),
                                 float(settings["t1"]))
    if x_phys is None:
        x_phys = np.asarray(case.initial_design(0.5 if args.value is None else args.value))
    elif x_phys.shape != (case.n_design,) and user:
        raise ValueError(f"The design has {x_phys.size} densities, the designed body of {args.case} "
                         f"{case.n_design}: give the design made for this case.")
    elif x_phys.shape != (case.n_design,):
        raise ValueError(f"The design has {x_phys.size} densities, the {case.mesh.nx} x {case.mesh.ny} rod "
                         f"{case.n_design}: give the --nx/--ny the design was made with.")
    return case, x_phys


def add_io_parsers(sub) -> None:
    """Add the `animate` and `export` subcommands to the `ffr-jax` subparsers `sub`."""
    p = sub.add_parser(
        "animate",
        help="animate the mechanism with the designed rod drawn deformed and coloured by density (GIF)",
        description="Simulate the case for a design and draw every frame: the rod's elements at their deformed "
                    "places (elastic displacement amplified, the factor shown), coloured by physical density, with "
                    "the crank and the slider guide. GIF through Pillow, or MP4 when --out ends in .mp4 and ffmpeg "
                    "is installed.",
    )
    _add_design_arguments(p)
    p.add_argument("--out", required=True, metavar="FILE", help="the animation (.gif, or .mp4 with ffmpeg)")
    p.add_argument("--frames", type=int, default=60, help="frames over [0, t1] (default 60)")
    p.add_argument("--fps", type=float, default=20.0, help="frames per second (default 20)")
    p.add_argument("--scale", type=float, default=None,
                   help="amplification of the elastic displacement (default: about 5 %% of the rod's length)")
    p.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance of the simulation (default 1e-8)")
    p.add_argument("--atol", type=float, default=1e-12, help="absolute tolerance of the simulation (default 1e-12)")
    p.set_defaults(func=_animate)

    p = sub.add_parser(
        "export",
        help="write a design for ParaView (VTU with density and mode shapes) and CAD (SVG/DXF outline)",
        description="The rod's mesh with the physical densities (cell data) and the mass-normalised mode shapes "
                    "(point data, frequencies as field data) as VTU; the iso-contour of the density (default 0.5) "
                    "as an SVG path and as DXF polylines, in millimetres.",
    )
    _add_design_arguments(p)
    p.add_argument("--vtu", metavar="FILE", help="VTU file to write")
    p.add_argument("--vtu-series", dest="vtu_series", metavar="FILE.pvd",
                   help="the motion for ParaView: FILE.pvd and one .vtu per time in FILE_vtu/ (the body at its rigid "
                        "placement, elastic displacement as point data for Warp By Vector, density as cell data)")
    p.add_argument("--frames", type=int, default=60, help="times of --vtu-series over [0, t1] (default 60)")
    p.add_argument("--svg", metavar="FILE", help="SVG outline to write")
    p.add_argument("--dxf", metavar="FILE", help="DXF outline to write")
    p.add_argument("--level", type=float, default=0.5, help="iso-value of the outline (default 0.5)")
    p.set_defaults(func=_export)


def _animate(args: argparse.Namespace) -> int:
    from ._animation import animate

    case, x_phys = _case_and_design(args)
    result = animate(case, x_phys, args.out, frames=args.frames, fps=args.fps, amplification=args.scale,
                     rtol=args.rtol, atol=args.atol)
    print(f"wrote {result.path}: {result.frames} frames over [0, {case.t1}] s, elastic displacement x "
          f"{result.amplification:g} (largest {1e3 * result.max_displacement:.4g} mm)")
    return 0


def _export(args: argparse.Namespace) -> int:
    from ._outline import density_outline, write_dxf, write_svg
    from ._vtu import write_vtu

    from ._vtu_series import write_vtu_series

    if args.vtu is None and args.svg is None and args.dxf is None and args.vtu_series is None:
        raise ValueError("Nothing to export: give --vtu, --vtu-series, --svg and/or --dxf.")
    if args.vtu_series is not None and not Path(args.vtu_series).suffix.lower() == ".pvd":
        raise ValueError(f"--vtu-series {args.vtu_series}: name the .pvd collection (e.g. motion.pvd).")
    case, x_phys = _case_and_design(args)
    if args.vtu is not None:
        print(f"wrote {write_vtu(args.vtu, case, x_phys)} (density, design, mode_1..mode_{case.n_modes})")
    if args.vtu_series is not None:
        written = write_vtu_series(args.vtu_series, case, x_phys, frames=args.frames)
        print(f"wrote {written} ({args.frames} times over [0, {case.t1}] s: elastic_displacement, density, design)")
    if args.svg is not None or args.dxf is not None:
        loops = len(density_outline(case, x_phys, args.level))
        for path, write in ((args.svg, write_svg), (args.dxf, write_dxf)):
            if path is not None:
                written = write(path, case, x_phys, level=args.level)
                print(f"wrote {written} ({loops} closed contour(s) at {args.level})")
    return 0
