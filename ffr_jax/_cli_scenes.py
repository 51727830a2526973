"""The scenes of the `ffr-jax` command line: their options, defaults and cases."""

SCENES = {
    "slider-crank": "the paper's reference case: a flexible rod driven by a crank, its end sliding on a line",
    "link-four-bar": "a crank-rocker four-bar whose coupler is a link with two pin holes and solid rims (gmsh mesh)",
}
# Options of each scene and their defaults.
# `atol`: the absolute tolerance of the solves, below the elastic coordinates (about 1e-5 for the
# slider-crank rod, 1e-7 for the link, whose interface modes are stiffer). `optimizer` (ffr-jax
# optimize): Adam for the rod; optimality criteria for the link, which is scale-free, while Adam's
# eps 1e-8 dominates its step at the link's gradients (~1e-10; benchmarks/RESULTS.md).
SCENE_DEFAULTS = {
    "slider-crank": {"nx": 100, "ny": 6, "modes": 6, "t1": 3.0, "atol": 1e-12, "optimizer": "adam"},
    "link-four-bar": {"mesh_size": 0.004, "modes": 4, "t1": 0.3, "atol": 1e-15, "optimizer": "oc"},
}


def scene_settings(scene: str, given: dict) -> dict:
    """The scene's settings: its defaults, overridden by the options `given` (`None` = not given).

    Raises `ValueError` for an option the scene does not have (e.g. `--nx` for link-four-bar).
    """
    defaults = SCENE_DEFAULTS[scene]
    foreign = sorted(k for k, v in given.items() if v is not None and k not in defaults
                     and any(k in other for other in SCENE_DEFAULTS.values()))
    if foreign:
        raise ValueError(f"{', '.join('--' + k.replace('_', '-') for k in foreign)}: not an option of the scene "
                         f"{scene} (its options: {', '.join('--' + k.replace('_', '-') for k in defaults)}).")
    return {k: (given.get(k) if given.get(k) is not None else v) for k, v in defaults.items()}


def make_case(scene: str, settings: dict):
    """The case of a CLI scene with settings from [`scene_settings`][]."""
    import ffr_jax as fj

    if scene == "slider-crank":
        return fj.cases.slider_crank(nx=settings["nx"], ny=settings["ny"], n_modes=settings["modes"], t1=settings["t1"])
    return fj.cases.link_four_bar(settings["t1"], mesh_size=settings["mesh_size"], n_modes=settings["modes"])


def describe(scene: str, case) -> str:
    """One line naming the scene's designed body and its size."""
    body = case.design
    if scene == "slider-crank":
        return f"slider-crank rod: {case.mesh.nx} x {case.mesh.ny} Q4 elements, {case.n_design} design variables"
    return (f"link-four-bar coupler: {body.mesh.n_elements} {type(body.model.element).__name__} elements "
            f"({body.mesh.n_elements - body.n_design} in the passive rims), {case.n_design} design variables, "
            f"{body.n_modes} eigenmodes + {body.reduction.n_q(body.mesh) - body.n_modes} interface modes")
