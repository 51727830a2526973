"""The spatial slider–crank with the rod as a solid of one layer of hexahedra (issue 27)."""

import equinox as eqx
import numpy as np

from .._checks import integer, number, positive
from .._dynamics._case import Case
from .._design.material import SIMP
from .._scene._laws import RampLaw
from ._solid_rod import solid_rod
from ._spatial_slider_crank import spatial_slider_crank_problem


def solid_slider_crank(nx: int = 100, ny: int = 6, n_modes: int = 6, t1: float = 3.0, *,
                       out_of_plane_modes: int = 0, poisson: float = 0.3, eccentricity: float = 0.1,
                       speed: float = 12 * np.pi, t_ramp: float = 2.0, length: float = 1.0, height: float = 0.06,
                       thickness: float = 0.01, material: SIMP = SIMP()) -> Case:
    """`slider_crank(..., spatial=True)` with the rod meshed as a solid: one layer of `H8` through its thickness.

    The mechanism, crank law, objective and coordinates are those of `slider_crank(..., spatial=True)` (spatial
    bodies and joints, independent coordinates the rod's `q`); the rod's body data come from its solid finite
    element model ([`solid_rod`][]: the same design variables as the planar rod, `n_modes` in-plane and
    `out_of_plane_modes` out-of-plane modes, markers A and B the node lines through the thickness) by
    [`solid_body_data`][]. With `poisson=0` its `psi` and design gradient are those of
    `slider_crank(nx, ny, n_modes, t1, rod=rod_body(nx, ny, n_modes, poisson=0.0))`: the in-plane modes are the
    planar ones, and the mechanism is symmetric about `z = 0`, so the out-of-plane modes stay unexcited.

    **Arguments:** as [`slider_crank`][]; `out_of_plane_modes` (default 0) and `poisson` (default 0.3) of the
    solid rod.

    **Returns:** a [`Case`][] whose design map is the [`SolidRod`][].
    """
    t1 = positive(t1, "solid_slider_crank(t1=...)", "It is the end time in s.")
    t_ramp = positive(t_ramp, "solid_slider_crank(t_ramp=...)", "It is the run-up time of the crank in s.")
    speed = number(speed, "solid_slider_crank(speed=...)")
    for name, value in (("nx", nx), ("ny", ny), ("n_modes", n_modes)):
        integer(value, f"solid_slider_crank({name}=...)", 1)
    length = positive(length, "solid_slider_crank(length=...)")
    if not 0 < number(eccentricity, "solid_slider_crank(eccentricity=...)") < length:
        raise ValueError(f"The crank eccentricity must lie in (0, l) = (0, {length}) for the slider–crank to "
                         f"assemble at every crank angle, got {eccentricity}.")
    rod = solid_rod(nx, ny, n_modes, out_of_plane_modes=out_of_plane_modes, length=length, height=height,
                    thickness=thickness, poisson=poisson, material=material)
    data = _uniform_body_data(rod)
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    return Case(problem=spatial_slider_crank_problem(None, eccentricity, law, t1, rod_data=data), design_map=rod)


@eqx.filter_jit
def _compiled_body_data(rod, x):
    return rod.body_data(x)


def _uniform_body_data(rod):
    """The body data of the uniform design `x = 0.5` (the scene template's), value-checked after the compiled
    computation."""
    data = _compiled_body_data(rod, rod.initial_design(0.5))
    return type(data)(**{name: getattr(data, name) for name in data.__dataclass_fields__})
