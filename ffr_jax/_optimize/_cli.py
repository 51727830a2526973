"""The `ffr-jax optimize` subcommand: volume-constrained minimisation of a case's objective."""

import argparse
import json
from pathlib import Path

import numpy as np

from .._api import METHODS
from .._cli_checks import optimize_options
from .._cli_scenes import SCENES, describe, make_case, scene_settings
from ._checkpoint import load_checkpoint
from ._driver import CHECKPOINT, optimize

# Settings that define a run: stored in its checkpoints, taken from there on --resume.
_DEFAULTS = {
    "volume": 0.5,
    "optimizer": None,  # the scene's default (ffr_jax._cli_scenes): adam for the rod, oc for the link
    "lr": 0.02,
    "move": 0.05,
    "filter_radius": 1.5,
    "method": "adjoint",
    "nx": None,  # the scene's settings: None takes the scene's default (ffr_jax._cli_scenes)
    "ny": None,
    "mesh_size": None,
    "modes": None,
    "t1": None,
    "rtol": 1e-8,
    "atol": None,
    "beta": 0.0,
    "beta_max": 32.0,
    "beta_every": 20,
    "eta": 0.5,
}


def add_optimize_parser(sub) -> None:
    """Add the `optimize` subcommand to the `ffr-jax` subparsers `sub`."""
    p = sub.add_parser(
        "optimize",
        help="minimise the case's objective over the densities at a fixed volume fraction",
        description=(
            "Volume-constrained topology optimisation of the rod: a density filter, the exact design "
            "gradient, Adam or optimality criteria, the projection onto the volume after every step. "
            "Writes DIR/log.csv, DIR/checkpoint.npz (every k steps), and at the end DIR/design.npz, "
            "DIR/design.png and DIR/convergence.png. A run's settings are stored in its checkpoint: "
            "--resume DIR takes them from there (options given again must agree)."
        ),
    )
    p.add_argument("case", choices=list(SCENES), help="the scene: " + "; ".join(f"{k}: {v}" for k, v in SCENES.items()))
    p.add_argument("--volume", type=float, help="volume fraction V in (x_min, 1] (default 0.5)")
    p.add_argument("--iters", type=int, default=50, help="total number of steps (default 50)")
    p.add_argument("--optimizer", choices=["adam", "oc"], help="optax.adam or optimality criteria (default: adam for slider-crank; oc for "
                        "link-four-bar, whose psi ~ 1e-8 and |grad| ~ 1e-10 leave Adam's steps to its eps)")
    p.add_argument("--lr", type=float, help="Adam learning rate (default 0.02)")
    p.add_argument("--move", type=float, help="OC move limit (default 0.05)")
    p.add_argument("--filter-radius", type=float,
                   help="density filter radius in element sizes, 0 = off (default 1.5)")
    p.add_argument("--projection-beta", dest="beta", type=float,
                   help="Heaviside projection of the filtered densities, starting sharpness beta_0 (default 0 = "
                        "no projection); beta doubles every --beta-every steps up to --beta-max")
    p.add_argument("--beta-max", type=float, help="largest projection sharpness (default 32)")
    p.add_argument("--beta-every", type=int, help="steps between doublings of beta (default 20)")
    p.add_argument("--projection-eta", dest="eta", type=float, help="projection threshold eta (default 0.5)")
    p.add_argument("--method", choices=sorted(METHODS),
                   help="sensitivity method (default adjoint)")
    p.add_argument("--out", metavar="DIR", help="output directory of a new run (default optimize-<case>)")
    p.add_argument("--resume", metavar="DIR", help="continue the run stored in DIR")
    p.add_argument("--checkpoint-every", type=int, default=10, metavar="K",
                   help="steps between checkpoints (default 10)")
    p.add_argument("--nx", type=int, help="slider-crank: elements along the rod (default 100)")
    p.add_argument("--ny", type=int, help="slider-crank: elements across the rod, even (default 6)")
    p.add_argument("--mesh-size", type=float, help="link-four-bar: target element size of the gmsh mesh in m "
                                                    "(default 0.004)")
    p.add_argument("--modes", type=int, help="retained eigenmodes (default 6; link-four-bar 4)")
    p.add_argument("--t1", type=float, help="end time in s (default 3; link-four-bar 0.3)")
    p.add_argument("--rtol", type=float, help="relative tolerance of the solves (default 1e-8)")
    p.add_argument("--atol", type=float,
                   help="absolute tolerance of the solves (default 1e-12; link-four-bar 1e-15; short runs have tiny "
                        "elastic coordinates)")
    p.add_argument("--no-progress", action="store_true", help="no progress line")
    p.set_defaults(func=_run)


def _settings(args: argparse.Namespace) -> tuple[Path, dict]:
    """The run directory and the settings: defaults < stored checkpoint (on --resume) < options."""
    settings = dict(_DEFAULTS, case=args.case)
    if args.resume is not None:
        directory = Path(args.resume)
        if args.out is not None and Path(args.out).resolve() != directory.resolve():
            raise ValueError(f"--out {args.out} and --resume {args.resume} name different directories; "
                             "a resumed run continues in its own directory.")
        settings.update(load_checkpoint(directory / CHECKPOINT).config)
    else:
        directory = Path(args.out if args.out is not None else f"optimize-{args.case}")
    given = {key: getattr(args, key) for key in _DEFAULTS if getattr(args, key) is not None}
    if args.resume is not None:
        differ = {key: value for key, value in given.items() if settings[key] != value}
        if differ:
            raise ValueError(f"--resume {args.resume}: the run was made with " + ", ".join(
                f"--{key.replace('_', '-')} {settings[key]}" for key in differ) + "; leave these options out "
                "or start a new run with --out.")
    settings.update(given)
    return directory, settings


def _run(args: argparse.Namespace) -> int:
    import optax

    import ffr_jax as fj

    directory, s = _settings(args)
    s.update(scene_settings(s["case"], s))
    optimize_options(s, args, directory, resume=args.resume is not None)
    case = make_case(s["case"], s)
    filt = fj.DensityFilter(case.design, s["filter_radius"])
    projection, beta = None, None
    if s["beta"] > 0.0:
        projection = fj.HeavisideProjection(s["eta"], x_min=case.material.x_min)
        beta = fj.beta_continuation(s["beta"], max(s["beta_max"], s["beta"]), every=s["beta_every"])
    constraint = fj.VolumeConstraint(s["volume"], x_min=case.material.x_min, filter=filt, projection=projection)
    if s["optimizer"] == "adam":
        optimizer = optax.adam(s["lr"])
    else:
        optimizer = fj.optimality_criteria(constraint, move=s["move"])
    fun = fj.make_objective(case, s["method"], filter=filt, projection=projection, rtol=s["rtol"], atol=s["atol"])
    projected = "" if beta is None else f", Heaviside projection beta {s['beta']} -> {s['beta_max']} (x2 every {s['beta_every']})"
    print(f"optimize {describe(s['case'], case)}, "
          f"V = {s['volume']}, {s['optimizer']}, filter radius {s['filter_radius']}{projected}, {args.iters} steps "
          f"-> {directory}")
    result = optimize(
        fun, case.initial_design(s["volume"]), optimizer, constraint, iterations=args.iters,
        directory=directory, resume=args.resume is not None, checkpoint_every=args.checkpoint_every,
        config=s, progress=not args.no_progress, beta=beta,
    )
    h = result.history
    # The last iterate was projected onto the volume with the last step's beta.
    beta_last = None if beta is None else beta(max(h.steps - 1, 0))
    x_phys = np.asarray(fj.physical_densities(result.x, filt, projection, beta_last))
    np.savez(directory / "design.npz", x=np.asarray(result.x), x_phys=x_phys, psi=h.value, volume=h.volume,
             max_change=h.change, beta=np.array(np.nan if beta_last is None else beta_last),
             config=np.array(json.dumps(s, sort_keys=True)))
    ax = fj.plot_design(case, x_phys, title=f"{s['case']}, V = {s['volume']}, {h.steps} steps")
    ax.figure.savefig(directory / "design.png", dpi=150)
    ax = fj.plot_history(h)
    ax.figure.savefig(directory / "convergence.png", dpi=150)
    if h.steps:
        print(f"psi {h.value[0]:.6e} -> {h.value[-1]:.6e} over {h.steps} steps, volume {h.volume[-1]:.6f}")
    print(f"wrote {directory}/design.npz, design.png, convergence.png, log.csv, {CHECKPOINT}")
    return 0
