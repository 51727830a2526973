"""The worked 3-D example (issue 27): a small solid connecting rod as the rod of the spatial slider–crank.

The rod ([`connecting_rod_groups`][]: two bores of different size joined by a shank, gmsh profile extruded into
hexahedra) is a [`SolidDesignedBody`][]: one SIMP density per element of the `web` (the shank and the eyes outside
the hubs); the hubs around the bores (`big_hub`, `small_hub`) are passive solid and carry no design variable.

**Reference conditions** (the floating frame's): every node of the big bore held in `x, y, z` (the frame's origin at
the big bore's centre, its orientation that of the bore), every node of the small bore held in `y, z` (its centre on
the frame's `x`-axis). They remove the six rigid motions and are mirror-symmetric about `z = 0`; holding whole bores
stiffens the eyes locally against ovalising (the pins would do much of that). The retained modes are the lowest of
the held part: in-plane and out-of-plane ones alike.

**Markers:** A the big bore's nodes (on the crank pin), B the small bore's (on the piston pin), each at the centroid
of its nodes (the bore's centre to round-off: gmsh spaces the circle's nodes evenly) and rotating with their
least-squares rigid fit ([`solid_body_data`][]).

**The mechanism** (default, `pin_offset=None`) is `slider_crank(..., spatial=True)`'s: crank hinge about `z`, the
rod hinged about `z` at A on the crank pin, B on the plane `y = 0`, compliance of the rod. A hinged rod's motion stays
in one plane and the part is mirror-symmetric, so its out-of-plane modes stay unexcited there.

**The offset crank pin** (`pin_offset=e`, `offset_slider_crank_problem`): the pin sits `e` along the crank axis
from the crank's plane, the rod hangs on it in a universal joint (arms: the pin axis and the rod's `y`-axis) and its
small end B runs on the `x`-axis in a ball joint: the rod runs tilted by `asin(e / l)` out of the crank's plane, and
the inertia loads in that plane load it across its own plane as well, exciting its out-of-plane modes. Options of
that scene: modal damping of the rod and the compliance averaged over a window `[t_a, t1]` ([`TimeWindow`][]), the
worked example's design objective (RESULTS: the average over a whole crank turn at steady speed, after a run-up
whose transient the damping removes, gives the design the loads of a full turn).
"""

from .._checks import integer, number, positive
from .._design.material import SIMP
from .._design.solid_design_map import SolidDesignMap
from .._design.solid_designed_body import solid_designed_body
from .._dynamics._case import Case
from .._scene._laws import RampLaw
from ._connecting_rod_mesh import connecting_rod_groups
from ._solid_slider_crank import _uniform_body_data
from ._offset_slider_crank import offset_slider_crank_problem
from ._spatial_slider_crank import spatial_slider_crank_problem


def connecting_rod(size: float = 0.008, n_layers: int = 2, n_modes: int = 6, *, length: float = 0.3,
                   poisson: float = 0.3, material: SIMP = SIMP()) -> SolidDesignMap:
    """The connecting rod as a design map (module docstring): `web` designed, hubs passive solid.

    **Arguments:** `size` the in-plane element size and `n_layers` hexahedra through the thickness (mesh of
    [`connecting_rod_groups`][], other dimensions its defaults); `n_modes` retained modes; `length` between the bore
    centres; `poisson`; `material`.

    **Returns:** a [`SolidDesignMap`][] for the scene body `"rod"`.
    """
    integer(n_layers, "connecting_rod(n_layers=...)", 1)
    integer(n_modes, "connecting_rod(n_modes=...)", 1)
    groups = connecting_rod_groups(length=positive(length, "connecting_rod(length=...)"),
                                   size=positive(size, "connecting_rod(size=...)"), n_layers=n_layers)
    body = solid_designed_body(groups, n_modes, markers=("big_bore", "small_bore"),
                               supports={"big_bore": "xyz", "small_bore": "yz"}, solid=("big_hub", "small_hub"),
                               poisson=poisson, material=material)
    return SolidDesignMap(body, "rod")


def connecting_rod_slider_crank(size: float = 0.008, n_layers: int = 2, n_modes: int = 6, t1: float = 0.5, *,
                                eccentricity: float = 0.06, speed: float = 12 * 3.141592653589793,
                                t_ramp: float = 0.5, length: float = 0.3, poisson: float = 0.3,
                                material: SIMP = SIMP(), pin_offset: float | None = None, damping_ratio: float = 0.0,
                                average_from: float | None = None) -> Case:
    """The spatial slider–crank with the solid connecting rod as its designed rod (module docstring).

    **Arguments:** `size`, `n_layers`, `n_modes`, `length`, `poisson`, `material` as [`connecting_rod`][]; `t1` the
    end time (s); the crank of radius `eccentricity` (m, `< length`) turns by the ramp law of the slider–crank,
    reaching `speed` (rad/s) after `t_ramp` (s). `pin_offset`: `None` (default) the hinged rod in the crank's plane,
    or the crank pin's offset `e` (m) along the crank axis (the universal-joint scene of the module docstring; `0.0`
    gives the hinged scene's motion); with a `pin_offset` only: `damping_ratio` of [`ModalDamping`][] on the rod
    (default 0) and `average_from` (`None`: the compliance integrated over `[0, t1]`; a time `t_a`: its time average
    over `[t_a, t1]`).

    **Returns:** a [`Case`][] whose design map is the [`SolidDesignMap`][]; `case.initial_design(0.5)` the uniform
    design of the `web`.
    """
    t1 = positive(t1, "connecting_rod_slider_crank(t1=...)", "It is the end time in s.")
    t_ramp = positive(t_ramp, "connecting_rod_slider_crank(t_ramp=...)", "It is the run-up time of the crank in s.")
    speed = number(speed, "connecting_rod_slider_crank(speed=...)")
    if not 0 < number(eccentricity, "connecting_rod_slider_crank(eccentricity=...)") < length:
        raise ValueError(f"The crank eccentricity must lie in (0, length) = (0, {length}) for the slider–crank to "
                         f"assemble at every crank angle, got {eccentricity}.")
    if pin_offset is None and (damping_ratio != 0.0 or average_from is not None):
        raise ValueError("damping_ratio and average_from are options of the offset-pin scene: give pin_offset (0.0 "
                         "for a pin in the crank's plane) with them.")
    if pin_offset is not None and not number(pin_offset, "connecting_rod_slider_crank(pin_offset=...)") ** 2 \
            + eccentricity**2 < length**2:
        raise ValueError(f"The crank pin offset e and the crank radius r must satisfy e^2 + r^2 < length^2 for the rod "
                         f"to reach the slider line at every crank angle, got e = {pin_offset}, r = {eccentricity}, "
                         f"length = {length}.")
    if not 0.0 <= number(damping_ratio, "connecting_rod_slider_crank(damping_ratio=...)") < 1.0:
        raise ValueError(f"damping_ratio must lie in [0, 1) (a modal damping ratio), got {damping_ratio}.")
    rod = connecting_rod(size, n_layers, n_modes, length=length, poisson=poisson, material=material)
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    if pin_offset is not None:
        problem = offset_slider_crank_problem(_uniform_body_data(rod), eccentricity,
                                              number(pin_offset, "connecting_rod_slider_crank(pin_offset=...)"), law,
                                              t1, damping_ratio=damping_ratio, average_from=average_from)
        return Case(problem=problem, design_map=rod)
    return Case(problem=spatial_slider_crank_problem(None, eccentricity, law, t1, rod_data=_uniform_body_data(rod)),
                design_map=rod)
