"""The `ffr-jax optimize` subcommand: volume-constrained minimisation of a case's objective."""

import argparse
import functools
import json
from pathlib import Path

import numpy as np

from .._api import METHODS
from .._checks import in_interval, number
from ._cli_checks import optimize_options, robust_options
from ._cli_scenes import SCENES, USER_CASE_HELP, case_name, describe, is_user_case, make_case, scene_settings
from ._checkpoint import load_checkpoint
from ._driver import CHECKPOINT, optimize
from .._optimize._mma import DEFAULT_MOVE
from .._optimize._projection import DEFAULT_BETA_EVERY, DEFAULT_BETA_MAX, DEFAULT_BETA_START, ROBUST_OBJECTIVES

# Settings that define a run: stored in its checkpoints, taken from there on --resume.
_DEFAULTS = {
    "volume": 0.5,
    "optimizer": None,  # the scene's default (ffr_jax._cli_scenes): adam for the rod, oc for the link
    "lr": 0.02,
    "move": 0.05,
    "mma_move": DEFAULT_MOVE,  # MMA's default
    "frequency_min": 0.0,
    "mass_max": 0.0,
    "stop_change": 0.0,
    "filter_radius": 1.5,
    "filter_length": None,  # a radius in the mesh's length unit instead (the same layout on a finer mesh)
    "method": "adjoint",
    "nx": None,  # the scene's settings: None takes the scene's default (ffr_jax._cli_scenes)
    "ny": None,
    "mesh_size": None,
    "modes": None,
    "t1": None,
    "rtol": 1e-8,
    "atol": None,
    "beta": None,  # the optimizer's: the default continuation with mma (fj.optimize's), no projection otherwise
    "beta_max": DEFAULT_BETA_MAX,
    "beta_every": DEFAULT_BETA_EVERY,
    "eta": 0.5,
    # The robust formulation of the projection (fj.HeavisideProjection's eta_eroded, eta_dilated, objective).
    "eta_eroded": None,
    "eta_dilated": None,
    "robust_objective": "max",
    "volume_per_body": None,
}
# The crank–rocker whose coupler and rocker are both designed (issue 14): its own mesh and run defaults.
_TWO_LINKS_DEFAULTS = {"nx": 40, "ny": 4, "modes": 3, "t1": 1.0, "atol": 1e-12, "optimizer": "mma"}


def add_optimize_parser(sub) -> None:
    """Add the `optimize` subcommand to the `ffr-jax` subparsers `sub`."""
    p = sub.add_parser(
        "optimize",
        help="minimise the case's objective over the densities under volume (and other) constraints",
        description=(
            "Topology optimisation of the rod: a density filter, the exact design gradient, and either Adam "
            "or optimality criteria with the projection onto the volume after every step, or MMA with the "
            "volume, a first-frequency bound and a mass bound as inequality constraints. "
            "Writes DIR/log.csv (one column per constraint), DIR/checkpoint.npz (every k steps), and at the end "
            "DIR/design.npz, DIR/design.png and DIR/convergence.png (objective and every constraint). A run's "
            "settings are stored in its checkpoint: --resume DIR takes them from there (options given again "
            "must agree)."
        ),
    )
    p.add_argument("case", type=case_name(("four-bar-two-links",)), metavar="CASE",
                   help="the scene: " + "; ".join(f"{k}: {v}" for k, v in SCENES.items())
                        + "; four-bar-two-links: the crank-rocker whose coupler and rocker are both flexible and "
                          "designed together (MMA, a filter per rod, defaults --nx 40 --ny 4 --modes 3 --t1 1); "
                        + USER_CASE_HELP)
    p.add_argument("--volume-per-body", dest="volume_per_body", type=float, nargs="+", metavar="V",
                   help="four-bar-two-links: one volume bound per rod (coupler rocker) instead of the shared --volume "
                        "(the area fraction of both rods together)")
    p.add_argument("--volume", type=float,
                   help="volume fraction V in (x_min, 1] (default 0.5): held exactly by adam and oc, "
                        "an upper bound for mma")
    p.add_argument("--iters", type=int, default=50, help="total number of steps (default 50)")
    p.add_argument("--optimizer", choices=["adam", "oc", "mma"],
                   help="optax.adam, optimality criteria, or the method of moving asymptotes with constraints "
                        "(default: adam for slider-crank; oc for link-four-bar, whose psi ~ 1e-8 and |grad| ~ 1e-10 "
                        "leave Adam's steps to its eps)")
    p.add_argument("--lr", type=float, help="Adam learning rate (default 0.02)")
    p.add_argument("--move", type=float, help="OC move limit (default 0.05)")
    p.add_argument("--mma-move", type=float, help="MMA move limit per step (default 0.2)")
    p.add_argument("--frequency-min", type=float, metavar="HZ",
                   help="MMA only: lower bound on the rod's first natural frequency in Hz (default 0 = none)")
    p.add_argument("--mass-max", type=float, metavar="KG",
                   help="MMA only: upper bound on the rod's mass in kg (default 0 = none)")
    p.add_argument("--stop-change", type=float,
                   help="stop once no variable changes by more than this in a step (default 0 = run all --iters)")
    p.add_argument("--filter-radius", type=float,
                   help="density filter radius in element sizes, 0 = off (default 1.5)")
    p.add_argument("--filter-length", type=float, metavar="M",
                   help="density filter radius in m instead of --filter-radius: the same length scale, and so the "
                        "same layout, on a finer mesh")
    p.add_argument("--projection-beta", dest="beta", type=float,
                   help="Heaviside projection of the filtered densities, starting sharpness beta_0; beta doubles "
                        "every --beta-every steps up to --beta-max (default: 1 with --optimizer mma, as fj.optimize "
                        "does for a projected objective, so that the run ends near a 0/1 design; 0 = no projection, "
                        "the default of adam and oc)")
    p.add_argument("--beta-max", type=float, help="largest projection sharpness (default 32)")
    p.add_argument("--beta-every", type=int, help="steps between doublings of beta (default 10)")
    p.add_argument("--projection-eta", dest="eta", type=float, help="projection threshold eta (default 0.5)")
    p.add_argument("--eta-eroded", type=float, metavar="ETA_E",
                   help="with --eta-dilated: the robust formulation of the projection (Wang, Lazarov, Sigmund 2011; "
                        "fj.HeavisideProjection's eta_eroded), a minimum member size: the filtered field is projected "
                        "at three thresholds, 0 < eta_dilated < eta < eta_eroded < 1 (e.g. 0.3 / 0.5 / 0.7), into an "
                        "eroded, a blueprint and a dilated design; the blueprint is the design reported, constrained "
                        "and drawn. Needs the projection (--optimizer mma, or --projection-beta > 0)")
    p.add_argument("--eta-dilated", type=float, metavar="ETA_D",
                   help="the robust formulation's lower threshold (with --eta-eroded)")
    p.add_argument("--robust-objective", choices=ROBUST_OBJECTIVES,
                   help="with --eta-eroded/--eta-dilated: the design(s) the objective is evaluated on; max (default): "
                        "the min-max over the three designs (their p-norm, three solves per step), or one design "
                        "(one solve per step; the min-max only where that design is the worst case)")
    p.add_argument("--method", choices=sorted(METHODS),
                   help="sensitivity method (default adjoint)")
    p.add_argument("--out", metavar="DIR", help="output directory of a new run (default optimize-<case>)")
    p.add_argument("--resume", metavar="DIR", help="continue the run stored in DIR")
    p.add_argument("--force-resume", action="store_true",
                   help="with --resume: continue even if the checkpoint's fingerprints (case, mesh, constraints, "
                        "optimizer settings) differ from the run built now")
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
    p.add_argument("--no-progress", action="store_true",
                   help="no progress report (a tqdm bar on a terminal, a line per tenth of the run otherwise)")
    p.set_defaults(func=_run)


def _settings(args: argparse.Namespace) -> tuple[Path, dict, set]:
    """The run directory, the settings (defaults < stored checkpoint (on --resume) < options), and the
    keys the stored run had (all of them for a new run)."""
    settings = dict(_DEFAULTS, case=args.case)
    if args.case == "four-bar-two-links":
        settings.update(_TWO_LINKS_DEFAULTS)
    stored = set(settings)
    if args.resume is not None:
        directory = Path(args.resume)
        if args.out is not None and Path(args.out).resolve() != directory.resolve():
            raise ValueError(f"--out {args.out} and --resume {args.resume} name different directories; "
                             "a resumed run continues in its own directory.")
        config = load_checkpoint(directory / CHECKPOINT).config
        if "case" in config and config["case"] != args.case:
            raise ValueError(f"--resume {args.resume} holds a run of {config['case']}, not {args.case}; resume it with "
                             f"ffr-jax optimize {config['case']} --resume {args.resume}, or start a {args.case} run "
                             "with --out.")
        settings.update(config)
        stored = set(config)
    else:
        if args.force_resume:
            raise ValueError("--force-resume applies to --resume DIR.")
        if args.out is not None and not args.out.strip():
            raise ValueError("--out '' names no directory (it would write into the current one); give a directory "
                             "name, or leave --out out for optimize-<case>.")
        name = Path(args.case.rpartition(":")[0]).stem if is_user_case(args.case) else args.case
        directory = Path(args.out if args.out is not None else f"optimize-{name}")
    given = {key: getattr(args, key) for key in _DEFAULTS if getattr(args, key) is not None}
    if args.resume is not None:
        differ = {key: value for key, value in given.items() if settings[key] != value}
        if differ:
            raise ValueError(f"--resume {args.resume}: the run was made with " + ", ".join(
                f"--{key.replace('_', '-')} {settings[key]}" for key in differ) + "; leave these options out "
                "or start a new run with --out.")
    settings.update(given)
    _check_bounds(settings)
    return directory, settings, stored


def _check_bounds(settings: dict) -> None:
    """The optional bounds and limits are finite numbers >= 0 (a NaN --mass-max used to drop the bound, as
    `nan > 0` is false), the MMA move limit lies in (0, 1]."""
    for key in ("frequency_min", "mass_max", "stop_change"):
        value = number(settings[key], f"--{key.replace('_', '-')}")
        if value < 0.0:
            raise ValueError(f"--{key.replace('_', '-')} must be >= 0 (0 = none), got {value}.")
    in_interval(settings["mma_move"], "--mma-move", 0.0, 1.0, low_open=True,
                advice="It is MMA's largest change of a density per step.")


def _default_beta(s: dict, stored: set, resume: bool) -> float:
    """The projection's starting sharpness when --projection-beta is not given: the default continuation of
    fj.optimize with MMA, none with adam and oc (and none for a resumed run stored before the setting existed)."""
    if s["beta"] is not None:
        return s["beta"]
    if resume and "beta" not in stored:
        return 0.0
    return DEFAULT_BETA_START if s["optimizer"] == "mma" else 0.0


@functools.cache
def _problem(scene: str, geometry: tuple, filter_radius: float, eta: float | None, method: str,
             rtol: float, atol: float, filter_length: float | None = None, robust: tuple | None = None):
    """`(case, filter, projection, objective)` of a setting, built once per process.

    `robust`: `(eta_eroded, eta_dilated, objective)` of the robust projection, or `None` (the plain one).

    Runs in one process with the same case and objective settings (tests, notebooks, a resumed run
    after a finished one) share the objective function, and so its compiled program (see
    [`make_step`][]), whatever optimizer or constraints they use.
    """
    from .._design.filter import DensityFilter
    from .._optimize._objective import make_objective
    from .._optimize._projection import HeavisideProjection
    from ._cli_io import slider_crank_case

    settings = dict(geometry)
    if scene == "slider-crank":  # the case object of the other commands (animate, export): shared programs
        case = slider_crank_case(int(settings["nx"]), int(settings["ny"]), int(settings["modes"]),
                                 float(settings["t1"]))
    else:
        case = make_case(scene, settings)
    if scene == "connecting-rod":  # a solid: the radius in metres (default 0.025 m, about two elements)
        filt = DensityFilter(case.design, 0.025 if filter_length is None else filter_length, scale=(1.0, 1.0, 1.0))
    else:
        filt = (DensityFilter(case.design, filter_radius) if filter_length is None
                else DensityFilter(case.design, filter_length, scale=(1.0, 1.0)))
    eroded, dilated, objective = (None, None, "max") if robust is None else robust
    projection = None if eta is None else HeavisideProjection(eta, x_min=case.material.x_min, eta_eroded=eroded,
                                                              eta_dilated=dilated, objective=objective)
    fun = make_objective(case, method, filter=filt, projection=projection, rtol=rtol, atol=atol)
    return case, filt, projection, fun


class RunStopped(RuntimeError):
    """`ffr-jax optimize` stopped by the file system (disk full, a read-only or vanished directory) or by
    Ctrl-C: one line that says what happened, what was kept and how to continue."""


def _run(args: argparse.Namespace) -> int:
    """`ffr-jax optimize`: the run, with a file-system error or Ctrl-C reported as [`RunStopped`][]."""
    try:
        return _run_command(args)
    except (OSError, KeyboardInterrupt) as err:
        raise RunStopped(_stopped(args, err)) from None


def _stopped(args: argparse.Namespace, err: BaseException) -> str:
    """What stopped the run, the last checkpoint it kept and the command that continues it."""
    if isinstance(err, KeyboardInterrupt):
        what = "interrupted (Ctrl-C)"
    else:
        where = f" ({err.filename})" if getattr(err, "filename", None) else ""
        what = f"stopped by the file system: {err.strerror or err}{where}"
    if args.resume is not None:
        directory = Path(args.resume)
    elif args.out:
        directory = Path(args.out)
    else:
        directory = Path(f"optimize-{Path(args.case.rpartition(':')[0]).stem if is_user_case(args.case) else args.case}")
    try:
        kept = load_checkpoint(directory / CHECKPOINT).iteration
    except Exception:  # noqa: BLE001 - no readable checkpoint is an answer here, not an error
        return f"optimize {what}; {directory} holds no readable checkpoint, so there is nothing to resume: start again."
    return (f"optimize {what}; the last checkpoint (step {kept}) is kept in {directory / CHECKPOINT}; continue with "
            f"ffr-jax optimize {args.case} --resume {directory}")


def _run_command(args: argparse.Namespace) -> int:
    import optax

    from ._plot_optimize import plot_design, plot_history
    from .._optimize._frequency import FrequencyConstraint
    from .._optimize._grey import grey_share
    from .._optimize._mass import MassConstraint
    from .._optimize._mma import MMA
    from .._optimize._objective import physical_densities
    from .._optimize._oc import optimality_criteria
    from .._optimize._projection import beta_continuation
    from .._optimize._volume import VolumeConstraint

    directory, s, stored = _settings(args)
    if s["case"] == "four-bar-two-links":
        s["beta"] = 0.0 if s["beta"] is None else s["beta"]  # no projection of a dict design from the shell
        optimize_options(s, args, directory, resume=args.resume is not None)
        config = {key: value for key, value in s.items() if key in stored or value != _DEFAULTS.get(key)}
        return _run_two_links(args, directory, s, config)
    if s["volume_per_body"] is not None:
        raise ValueError(f"--volume-per-body is for a scene with several designed bodies; {s['case']} designs one.")
    s.update(scene_settings(s["case"], s))
    s["beta"] = _default_beta(s, stored, args.resume is not None)
    optimize_options(s, args, directory, resume=args.resume is not None)
    robust = robust_options(s)
    if robust is not None and s["beta"] == 0.0:
        raise ValueError("--eta-eroded/--eta-dilated: the robust formulation is a form of the projection, and this run "
                         f"has none ({s['optimizer']} without --projection-beta, or --projection-beta 0); give "
                         "--projection-beta 1 (the continuation) or --optimizer mma (projects by default).")
    if s["filter_length"] is not None:
        in_interval(s["filter_length"], "--filter-length", 0.0, float("inf"),
                    advice="It is the filter radius in m (0 = no filter).")
    # Runs stored before a setting existed resume with its default (and keep their stored config).
    config = {key: value for key, value in s.items() if key in stored or value != _DEFAULTS.get(key)}
    if "beta" not in stored:  # a run stored before beta was a setting: no projection, and none stored
        config.pop("beta", None)
    # The case's own settings (mesh, modes, t1) key the shared objective; the optimizer and tolerances do not.
    geometry = tuple(sorted((k, v) for k, v in scene_settings(s["case"], s).items()
                            if k not in ("optimizer", "atol")))
    case, filt, projection, fun = _problem(s["case"], geometry, float(s["filter_radius"]),
                                           float(s["eta"]) if s["beta"] > 0.0 else None, s["method"],
                                           float(s["rtol"]), float(s["atol"]),
                                           None if s["filter_length"] is None else float(s["filter_length"]),
                                           robust)
    beta = None
    if s["beta"] > 0.0:
        beta = beta_continuation(s["beta"], max(s["beta_max"], s["beta"]), every=s["beta_every"])
    constraint = VolumeConstraint(s["volume"], x_min=case.material.x_min, filter=filt, projection=projection)
    constraints = [constraint]
    if s["optimizer"] != "mma" and (s["frequency_min"] > 0.0 or s["mass_max"] > 0.0):
        raise ValueError(f"--frequency-min and --mass-max need --optimizer mma; {s['optimizer']} holds only the "
                         "volume (by projection).")
    if s["frequency_min"] > 0.0:
        constraints.append(FrequencyConstraint(case, s["frequency_min"], filter=filt, projection=projection))
    if s["mass_max"] > 0.0:
        constraints.append(MassConstraint(case.design, s["mass_max"], filter=filt, projection=projection))
    if s["optimizer"] == "adam":
        optimizer = optax.adam(s["lr"])
    elif s["optimizer"] == "oc":
        optimizer = optimality_criteria(constraint, move=s["move"])
    else:
        optimizer = MMA(case.material.x_min, 1.0, move=s["mma_move"])
    projected = "" if beta is None else f", Heaviside projection beta {s['beta']} -> {s['beta_max']} (x2 every {s['beta_every']})"
    if robust is not None:
        projected += (f", robust: eroded / blueprint / dilated at eta {robust[0]:g} / {s['eta']:g} / {robust[1]:g}, "
                      f"objective {robust[2]}")
    bounds = "".join(f", {c.name} {'>=' if isinstance(c, FrequencyConstraint) else '<='} "
                     f"{c.minimum if isinstance(c, FrequencyConstraint) else c.bound:g}" for c in constraints[1:])
    radius = (f"filter radius {s['filter_radius']}" if s["filter_length"] is None
              else f"filter radius {s['filter_length']:g} m")
    if s["case"] == "connecting-rod" and s["filter_length"] is None:
        radius = "filter radius 0.025 m"  # the solid's default (_problem)
    print(f"optimize {describe(s['case'], case)}, "
          f"V = {s['volume']}{bounds}, {s['optimizer']}, {radius}{projected}, "
          f"{args.iters} steps -> {directory}")
    result = optimize(
        fun, case.initial_design(s["volume"]), optimizer, constraints if s["optimizer"] == "mma" else constraint,
        iterations=args.iters, directory=directory, resume=args.resume is not None,
        checkpoint_every=args.checkpoint_every, config=config, progress=not args.no_progress, beta=beta,
        stop_change=s["stop_change"] if s["stop_change"] > 0.0 else None, force_resume=args.force_resume,
    )
    h = result.history
    # The last iterate was projected onto the volume with the last step's beta.
    beta_last = None if beta is None else beta(max(h.steps - 1, 0))
    x_phys = np.asarray(physical_densities(result.x, filt, projection, beta_last))
    grey = float(grey_share(x_phys))
    np.savez(directory / "design.npz", x=np.asarray(result.x), x_phys=x_phys, psi=h.value, volume=h.volume,
             grey=np.array(grey), grey_history=h.grey_values,
             max_change=h.change, beta=np.array(np.nan if beta_last is None else beta_last),
             config=np.array(json.dumps(s, sort_keys=True)), constraint_names=np.array(json.dumps(list(h.names))),
             constraint_history=h.constraint_values, constraints=np.asarray(result.constraints))
    bound = f"V = {s['volume']}" if s["optimizer"] != "mma" else f"V = {x_phys.mean():.3f} (<= {s['volume']})"
    title = f"{s['case']}, {s['optimizer']}, {bound}, {h.steps} steps"
    if s["case"] == "connecting-rod":  # a solid: the surface of x_phys >= 0.5 from two views
        from ._solid_render import plot_solid_design

        plot_solid_design(case.design, x_phys, directory / "design.png", title=title)
    else:
        ax = plot_design(case, x_phys, title=title)
        ax.figure.savefig(directory / "design.png", dpi=150)
    ax = plot_history(h)
    ax.figure.savefig(directory / "convergence.png", dpi=150)
    if h.steps:
        print(f"psi {h.value[0]:.6e} -> {h.value[-1]:.6e} over {h.steps} steps, volume {h.volume[-1]:.6f}")
    print(f"grey share of the final design (0.1 < x_phys < 0.9): {100 * grey:.1f} %"
          + ("" if beta_last is None else f" at beta {beta_last:g}"))
    for line in result.descriptions:
        print(f"  constraint at the final design: {line}")
    if not result.feasible:
        print("  the final design violates a constraint (see above): more steps, or bounds that admit a design")
    print(f"wrote {directory}/design.npz, design.png, convergence.png, log.csv, {CHECKPOINT}")
    return 0


def _run_two_links(args: argparse.Namespace, directory: Path, s: dict, config: dict) -> int:
    """`optimize four-bar-two-links`: coupler and rocker designed together (a dict design through MMA)."""
    from .. import cases
    from ._plot_optimize import plot_designs, plot_history
    from .._design.filter import DensityFilter
    from .._optimize._mma import MMA
    from .._optimize._grey import grey_share
    from .._optimize._objective import make_objective, physical_densities
    from .._optimize._pytree import OnBody
    from .._optimize._volume import VolumeConstraint

    unsupported = [f"--{key.replace('_', '-')}" for key in ("frequency_min", "mass_max", "beta", "filter_length",
                                                            "eta_eroded", "eta_dilated") if s[key] not in (None, 0.0)]
    if s["optimizer"] != "mma":
        unsupported.append(f"--optimizer {s['optimizer']} (a dict design needs mma)")
    if unsupported:
        raise ValueError(f"four-bar-two-links does not take {', '.join(unsupported)}: it runs MMA with volume bounds "
                         "(--volume shared, or --volume-per-body VC VR).")
    case = cases.four_bar_two_links(int(s["nx"]), int(s["ny"]), int(s["modes"]), float(s["t1"]))
    names = case.design_map.names
    filters = {name: DensityFilter(body, float(s["filter_radius"])) for name, body in case.design_map.bodies.items()}
    x_min = min(body.material.x_min for body in case.design_map.bodies.values())
    if s["volume_per_body"] is not None:
        if len(s["volume_per_body"]) != len(names):
            raise ValueError(f"--volume-per-body takes one fraction per designed rod {list(names)}, got "
                             f"{s['volume_per_body']}.")
        volumes = dict(zip(names, s["volume_per_body"]))
        constraints = [OnBody(VolumeConstraint(v, x_min=x_min, filter=filters[name]), name)
                       for name, v in volumes.items()]
        bound = ", ".join(f"V_{name} <= {v}" for name, v in volumes.items())
    else:
        volumes = {name: s["volume"] for name in names}
        constraints = [VolumeConstraint(s["volume"], x_min=x_min, filter=filters)]
        bound = f"V (both rods) <= {s['volume']}"
    fun = make_objective(case, s["method"], filter=filters, rtol=float(s["rtol"]), atol=float(s["atol"]))
    sizes = ", ".join(f"{n} {b.mesh.nx} x {b.mesh.ny}" for n, b in case.design_map.bodies.items())
    print(f"optimize four-bar-two-links: {sizes} elements, {case.design_map.design_sizes} densities, {bound}, mma, "
          f"filter radius {s['filter_radius']}, {args.iters} steps -> {directory}")
    result = optimize(fun, case.initial_design(volumes), MMA(x_min, 1.0, move=s["mma_move"]), constraints,
                      iterations=args.iters, directory=directory, resume=args.resume is not None,
                      checkpoint_every=args.checkpoint_every, config=config, progress=not args.no_progress,
                      stop_change=s["stop_change"] if s["stop_change"] > 0.0 else None,
                      force_resume=args.force_resume)
    h = result.history
    x_phys = {name: np.asarray(v) for name, v in physical_densities(result.x, filters, None).items()}
    np.savez(directory / "design.npz", psi=h.value, config=np.array(json.dumps(s, sort_keys=True)),
             constraint_names=np.array(json.dumps(list(h.names))), constraint_history=h.constraint_values,
             **{f"x_{name}": np.asarray(result.x[name]) for name in names},
             **{f"x_phys_{name}": x_phys[name] for name in names})
    volume_text = ", ".join(f"{name} {x_phys[name].mean():.3f}" for name in names)
    grey = float(grey_share(x_phys))
    fig = plot_designs(case, x_phys, title=f"four-bar-two-links, mma, {bound}, {h.steps} steps")
    fig.savefig(directory / "design.png", dpi=150)
    ax = plot_history(h)
    ax.figure.savefig(directory / "convergence.png", dpi=150)
    if h.steps:
        print(f"psi {h.value[0]:.6e} -> {h.value[-1]:.6e} over {h.steps} steps, mean density {volume_text}")
    print(f"grey share of the final design (0.1 < x_phys < 0.9, both rods): {100 * grey:.1f} %")
    for line in result.descriptions:
        print(f"  constraint at the final design: {line}")
    print(f"wrote {directory}/design.npz, design.png, convergence.png, log.csv, {CHECKPOINT}")
    return 0
