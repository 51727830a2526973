"""The scenes of the `ffr-jax` command line: their options, defaults and cases, and a user's own case
given as `my_case.py:make_case` (a Python file and a function in it that returns an `ffr_jax.Case`)."""

import functools
import importlib.util
from pathlib import Path

SCENES = {
    "slider-crank": "the paper's reference case: a flexible rod driven by a crank, its end sliding on a line",
    "link-four-bar": "a crank-rocker four-bar whose coupler is a link with two pin holes and solid rims (gmsh mesh)",
    "connecting-rod": "a solid connecting rod (gmsh, two layers of hexahedra) on a crank pin offset 30 mm along its axis, "
                      "3000 rpm, compliance averaged over the last half of the motion",
}
# Options of each scene and their defaults.
# `atol`: the absolute tolerance of the solves, below the elastic coordinates (about 1e-5 for the
# slider-crank rod, 1e-7 for the link, whose interface modes are stiffer). `optimizer` (ffr-jax
# optimize): Adam for the rod; optimality criteria for the link, which is scale-free, while Adam's
# eps 1e-8 dominates its step at the link's gradients (~1e-10; benchmarks/RESULTS.md).
SCENE_DEFAULTS = {
    "slider-crank": {"nx": 100, "ny": 6, "modes": 6, "t1": 3.0, "atol": 1e-12, "optimizer": "adam"},
    "link-four-bar": {"mesh_size": 0.004, "modes": 4, "t1": 0.3, "atol": 1e-15, "optimizer": "oc"},
    "connecting-rod": {"mesh_size": 0.016, "modes": 4, "t1": 0.04, "atol": 1e-12, "optimizer": "mma"},
}
# The connecting rod's scene (issue 27's worked example, benchmarks/RESULTS.md): crank 0.06 m, its pin 0.03 m along
# the crank axis, a jerk-free run-up to 100 pi rad/s (3000 rpm) in t1 / 4, 5 % modal damping of the rod, the
# compliance averaged over [t1 / 2, t1] (one crank turn at the default t1 = 0.04 s). Four modes: with two, the second
# and third (both in-plane, 640-780 Hz) cross during an optimisation and psi jumps as they swap (RESULTS).
CONNECTING_ROD = {"n_layers": 2, "pin_offset": 0.03, "speed": 100 * 3.141592653589793, "damping_ratio": 0.05}


# A user's case takes no scene options (its function sets the mesh, modes and times itself).
USER_CASE_DEFAULTS = {"atol": 1e-12, "optimizer": "mma"}
USER_CASE_HELP = ("or a user's case FILE.py:FUNCTION, a Python file with a function of no arguments that returns an "
                  "ffr_jax.Case with one designed body (e.g. my_case.py:make_case)")


def is_user_case(name: str) -> bool:
    """Whether a case argument names a user's case, `FILE.py:FUNCTION`."""
    path, _, function = name.rpartition(":")
    return path.endswith(".py") and function.isidentifier()


def case_name(extra: tuple = ()):
    """An argparse `type` for the case argument: a scene of [`SCENES`][] (or of `extra`) or `FILE.py:FUNCTION`."""
    import argparse

    def check(name: str) -> str:
        if name in SCENES or name in extra or is_user_case(name):
            return name
        raise argparse.ArgumentTypeError(
            f"invalid case {name!r}: choose one of {', '.join([*SCENES, *extra])}, or give a user's case as "
            "FILE.py:FUNCTION (e.g. my_case.py:make_case)")

    return check


def load_user_case(name: str):
    """The case that `FUNCTION()` of `FILE.py` returns, for `name = "FILE.py:FUNCTION"` (each file and
    function loaded once per process, so the commands run in one process share its compiled programs).

    Raises `ValueError` when the file, the function or the returned case is not what the CLI needs.
    """
    path, _, function = name.rpartition(":")
    resolved = Path(path).expanduser().resolve()
    if not resolved.is_file():
        raise ValueError(f"No user case file {path}: give FILE.py:FUNCTION with an existing Python file.")
    return _load_user_case(str(resolved), resolved.stat().st_mtime_ns, function, name)


@functools.cache
def _load_user_case(path: str, mtime_ns: int, function: str, name: str):
    from .. import cases
    from .._dynamics._case import Case

    spec = importlib.util.spec_from_file_location(f"ffr_jax_user_case_{abs(hash((path, mtime_ns)))}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    make = getattr(module, function, None)
    if not callable(make):
        raise ValueError(f"{name}: {Path(path).name} defines no function {function!r} (define `def {function}(): "
                         "return case`).")
    case = make()
    if not isinstance(case, Case):
        raise ValueError(f"{name}: {function}() returned {type(case).__name__}, not an ffr_jax.Case (e.g. "
                         "fj.cases.slider_crank(rod=...)).")
    if len(case.design_map.names) != 1:
        raise ValueError(f"{name}: the commands take a case with one designed body; this one designs "
                         f"{list(case.design_map.names)}.")
    return case


def scene_settings(scene: str, given: dict) -> dict:
    """The scene's settings: its defaults, overridden by the options `given` (`None` = not given).

    Raises `ValueError` for an option the scene does not have (e.g. `--nx` for link-four-bar).
    """
    defaults = USER_CASE_DEFAULTS if is_user_case(scene) else SCENE_DEFAULTS[scene]
    foreign = sorted(k for k, v in given.items() if v is not None and k not in defaults
                     and any(k in other for other in SCENE_DEFAULTS.values()))
    if foreign:
        raise ValueError(f"{', '.join('--' + k.replace('_', '-') for k in foreign)}: not an option of the scene "
                         f"{scene} (its options: {', '.join('--' + k.replace('_', '-') for k in defaults)}).")
    return {k: (given.get(k) if given.get(k) is not None else v) for k, v in defaults.items()}


def make_case(scene: str, settings: dict):
    """The case of a CLI scene with settings from [`scene_settings`][]."""
    from .. import cases

    if is_user_case(scene):
        return load_user_case(scene)
    if scene == "slider-crank":
        return cases.slider_crank(nx=settings["nx"], ny=settings["ny"], n_modes=settings["modes"], t1=settings["t1"])
    if scene == "connecting-rod":
        t1 = settings["t1"]
        return cases.connecting_rod_slider_crank(settings["mesh_size"], n_modes=settings["modes"], t1=t1,
                                                 t_ramp=t1 / 4, average_from=t1 / 2, **CONNECTING_ROD)
    return cases.link_four_bar(settings["t1"], mesh_size=settings["mesh_size"], n_modes=settings["modes"])


def describe(scene: str, case) -> str:
    """One line naming the scene's designed body and its size."""
    body = case.design
    if is_user_case(scene):
        return (f"{scene}: body {case.design_map.names[0]!r}, {body.mesh.n_elements} "
                f"{type(body.model.element).__name__} elements, {case.n_design} design variables, "
                f"{body.reduction.n_q(body.mesh)} shape vectors")
    if scene == "slider-crank":
        return f"slider-crank rod: {case.mesh.nx} x {case.mesh.ny} Q4 elements, {case.n_design} design variables"
    if scene == "connecting-rod":
        return (f"connecting rod: {body.mesh.n_elements} H8 elements ({body.mesh.n_elements - case.n_design} in the "
                f"passive hubs), {case.n_design} design variables, {body.n_modes} eigenmodes, crank pin offset "
                f"{CONNECTING_ROD['pin_offset']} m")
    return (f"link-four-bar coupler: {body.mesh.n_elements} {type(body.model.element).__name__} elements "
            f"({body.mesh.n_elements - body.n_design} in the passive rims), {case.n_design} design variables, "
            f"{body.n_modes} eigenmodes + {body.reduction.n_q(body.mesh) - body.n_modes} interface modes")
