"""A crank–rocker four-bar whose coupler and rocker are both flexible, designed rods (issue 14)."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._design.material import SIMP
from .._design.modal.auto import AutoModes
from .._design.modal.base import AbstractModalSolver
from .._dynamics._model import choose_partition
from .._objective._compliance import Compliance
from .._dynamics._problem import Problem
from .._scene._angle_driver import AngleDriver
from .._scene._body import Body
from .._scene._ground_revolute import GroundRevolute
from .._scene._laws import RampLaw
from .._scene._revolute import Revolute
from .._scene._scene import Scene
from ._four_bar import check_grashof, rigid_four_bar_position, uniform_bar
from ._rod import rod_body

LINKS = ("coupler", "rocker")


def _two_links_guess(t, y, scene):
    """Rigid-body estimate of the nine dependent coordinates (crank, coupler frame, rocker frame).

    Both rods are hinged–hinged: their far joint B moves elastically along the frame's x-axis only,
    so the chords are `L + u_x(B)` of each rod (`y = (q_coupler, q_rocker)`) and the estimate is the
    rigid four-bar of those chords, exact up to Newton's last digits.
    """
    phi = scene.constraints[1].angle(t)
    crank, coupler, rocker = (b.data for b in scene.bodies)
    n_c = coupler.n_modes
    pivot = scene.constraints[4].point
    chord = coupler.marker_positions[1, 0] + coupler.marker_modes[1, 0] @ y[:n_c]
    rocker_chord = rocker.marker_positions[1, 0] + rocker.marker_modes[1, 0] @ y[n_c:]
    pin, tip = rigid_four_bar_position(phi, chord, crank.marker_positions[1, 0], rocker_chord, pivot)
    c = tip - pin
    r = tip - pivot
    zero = jnp.zeros_like(phi)
    return jnp.stack([zero, zero, phi, pin[0], pin[1], jnp.arctan2(c[1], c[0]), pivot[0], pivot[1],
                      jnp.arctan2(r[1], r[0])])


def four_bar_two_links(
    nx: int = 60,
    ny: int = 6,
    n_modes: int = 4,
    t1: float = 1.0,
    *,
    rocker_nx: int | None = None,
    rocker_ny: int | None = None,
    rocker_modes: int | None = None,
    designed: tuple[str, ...] = LINKS,
    frozen=None,
    crank: float = 0.2,
    rocker: float = 0.8,
    ground: float = 0.9,
    speed: float = 4 * np.pi,
    t_ramp: float = 1.0,
    crank_mass: float = 0.5,
    length: float = 1.0,
    height: float = 0.06,
    thickness: float = 0.01,
    material: SIMP = SIMP(),
    modal_solver: AbstractModalSolver = AutoModes(),
) -> Case:
    """A crank–rocker four-bar with a rigid crank and two flexible, designed rods: coupler and rocker.

    The mechanism of [`four_bar`][] with its rigid rocker replaced by a second rod of
    REFERENCE_CASE §1–2 (length `rocker`, same cross-section and SIMP law): bodies `"crank"` (a
    uniform bar about the origin, angle prescribed by the run-up law of paper eqs. 45–46),
    `"coupler"` (A pinned to the crank tip, B to the rocker's B) and `"rocker"` (A pinned to the
    ground at `(ground, 0)`). Each rod has its own mesh, modal basis (hinged–hinged, `n_modes`
    resp. `rocker_modes`) and design. Coordinates
    `y_r = (crank R, theta | coupler R, theta, q_c | rocker R, theta, q_r)`, independent
    `y = (q_c, q_r)`, the nine rigid coordinates dependent. Initial state at rest, `phi = 0`,
    `q = 0` (the same for every design). The objective is the sum of both rods' integral
    compliances (paper eq. 49): `psi = int_0^t1 q_c^T K_c q_c + q_r^T K_r q_r dt`. A stiffer
    coupler changes the load on the rocker, so the two designs interact.

    Designs are a dict `{"coupler": x_c, "rocker": x_r}`; `ffr_jax.value_and_grad(case, x)`
    gives the gradient with respect to both by one forward and one adjoint solve.

    **Arguments:**
    - `nx`, `ny`, `n_modes`: the coupler's grid and retained modes; `rocker_nx`, `rocker_ny`,
      `rocker_modes`: the rocker's (default: `round(nx * rocker / length)` (even), `ny`, `n_modes`,
      i.e. the same element size and modes per body).
    - `t1`: end time.
    - `designed`: the rods whose designs are design variables (default both). A rod not in it is
      *frozen*: its data come from the density vector `frozen[name]` (default uniform 0.5) and
      stay fixed; e.g. `designed=("coupler",), frozen={"rocker": x_r}` is the one-body case of
      the same mechanism.
    - `crank`, `rocker`, `ground`: link lengths (the coupler's is `length`); Grashof crank–rocker.
    - `speed`, `t_ramp`, `crank_mass`: crank run-up and mass.
    - `length`, `height`, `thickness`, `material`, `modal_solver`: the rods.

    **Returns:** a [`Case`][] whose design map designs the bodies in `designed`.
    """
    check_grashof(crank, length, rocker, ground)
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    designed = (designed,) if isinstance(designed, str) else tuple(designed)
    unknown = [name for name in designed if name not in LINKS]
    if unknown or not designed or len(set(designed)) != len(designed):
        raise ValueError(f"designed must name one or both of {LINKS} once each, got {designed!r}.")
    frozen = dict(frozen or {})
    wrong = [name for name in frozen if name not in LINKS or name in designed]
    if wrong:
        raise ValueError(f"frozen names {wrong}, which are not frozen rods of this case: frozen rods are those of "
                         f"{LINKS} not in designed={designed!r}.")
    if rocker_nx is None:
        rocker_nx = max(4, int(round(nx * rocker / length)))
    rocker_ny = ny if rocker_ny is None else rocker_ny
    rocker_modes = n_modes if rocker_modes is None else rocker_modes
    rods = {
        "coupler": rod_body(nx, ny, n_modes, length=length, height=height, thickness=thickness, material=material,
                            modal_solver=modal_solver),
        "rocker": rod_body(rocker_nx, rocker_ny, rocker_modes, length=rocker, height=height, thickness=thickness,
                           material=material, modal_solver=modal_solver),
    }
    data = {}
    for name, rod in rods.items():
        if name in designed:
            data[name] = rod.uniform_body_data()
        else:
            x = (rod.initial_design(0.5) if name not in frozen
                 else rod.domain.check(jnp.asarray(frozen[name], float), rod.material.x_min, body=name))
            data[name] = rod.body_data(x)
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    scene = Scene(
        bodies=(
            Body("crank", uniform_bar(crank_mass, crank)),
            Body("coupler", data["coupler"]),
            Body("rocker", data["rocker"]),
        ),
        constraints=(
            GroundRevolute(body=0, marker=0, point=(0.0, 0.0)),
            AngleDriver(body=0, angle=law),
            Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0),
            Revolute(body_i=1, marker_i=1, body_j=2, marker_j=1),
            GroundRevolute(body=2, marker=0, point=(ground, 0.0)),
        ),
    )
    n_r = scene.n_coordinates
    rocker_start = 6 + n_modes
    rigid = (0, 1, 2, 3, 4, 5, rocker_start, rocker_start + 1, rocker_start + 2)
    y_r0 = jnp.zeros(n_r).at[np.asarray(rigid)].set(_two_links_guess(0.0, jnp.zeros(n_modes + rocker_modes), scene))
    partition = choose_partition(scene, 0.0, y_r0, prefer_dependent=rigid)
    if partition.dependent != rigid:
        raise ValueError(f"The four-bar's rigid coordinates {rigid} are not a regular dependent set at phi = 0.")
    problem = Problem(scene, t1, positions=y_r0, objective=Compliance(body=1) + Compliance(body=2),
                      partition=partition, dependent_guess=_two_links_guess)
    return Case(problem=problem, design_map=DesignMap({name: rods[name] for name in designed}))
