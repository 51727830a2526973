"""A crank–rocker four-bar linkage with a flexible coupler."""

import jax.numpy as jnp
import numpy as np

from .._scene._body_data import rigid_body_data
from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._design.material import SIMP
from .._dynamics._model import choose_partition
from .._objective._compliance import Compliance
from .._dynamics._problem import Problem
from .._scene._angle_driver import AngleDriver
from .._scene._body import Body
from .._scene._ground_revolute import GroundRevolute
from .._scene._laws import RampLaw
from .._scene._revolute import Revolute
from .._scene._scene import Scene
from ._rod import rod_body


def uniform_bar(mass: float, length: float):
    """Rigid body data of a slender uniform bar from its frame origin (marker 0) to `(length, 0)` (marker 1)."""
    return rigid_body_data(mass, (0.5 * mass * length, 0.0), mass * length**2 / 3.0, [[0.0, 0.0], [length, 0.0]])


def check_grashof(crank: float, coupler: float, rocker: float, ground: float) -> None:
    """Raise a `ValueError` unless the link lengths make a Grashof crank–rocker (the crank turns fully)."""
    links = {"crank": crank, "coupler": coupler, "rocker": rocker, "ground": ground}
    if min(links.values()) <= 0:
        raise ValueError(f"All link lengths must be positive, got {links}.")
    shortest, longest = min(links.values()), max(links.values())
    if crank != shortest or shortest + longest > sum(links.values()) - shortest - longest:
        raise ValueError(
            f"The link lengths {links} do not make a Grashof crank–rocker (the crank must be the "
            "shortest link and shortest + longest <= sum of the other two): the crank cannot turn "
            "fully and the linkage would fail to assemble during the run. Shorten the crank or "
            "change the other links."
        )


def rigid_four_bar_position(phi, chord, crank, rocker, pivot):
    """Rigid four-bar position analysis on the assembled branch (rocker tip left of `P -> O2`).

    With the crank pin `P = crank (cos phi, sin phi)`, the rocker pivot `O2 = pivot` and a coupler
    of length `chord`, the rocker tip `Q` is the intersection of the circles `|Q - P| = chord`
    and `|Q - O2| = rocker` that lies to the left of the direction `P -> O2` (the branch the
    linkage of [`four_bar`][] is assembled on).

    **Returns:** `(P, Q)`, each `(2,)`.
    """
    pin = crank * jnp.stack([jnp.cos(phi), jnp.sin(phi)])
    d_vec = pivot - pin
    d = jnp.sqrt(d_vec @ d_vec)
    e = d_vec / d
    along = (chord**2 - rocker**2 + d**2) / (2 * d)
    across = jnp.sqrt(jnp.maximum(chord**2 - along**2, 0.0))
    tip = pin + along * e + across * jnp.stack([-e[1], e[0]])
    return pin, tip


def _four_bar_guess(t, y, scene):
    """Rigid-body estimate of the dependent coordinates (crank, coupler frame, rocker) on the branch.

    The geometry is read from the scene. The coupler chord is `L + u_x(B)` (B moves elastically
    along the frame's x-axis only), so the estimate is exact up to Newton's last digits.
    """
    phi = scene.constraints[1].angle(t)
    crank, rod, rocker = (b.data for b in scene.bodies)
    pivot = scene.constraints[4].point
    chord = rod.marker_positions[1, 0] + rod.marker_modes[1, 0] @ y
    pin, tip = rigid_four_bar_position(phi, chord, crank.marker_positions[1, 0], rocker.marker_positions[1, 0], pivot)
    c = tip - pin
    r = tip - pivot
    zero = jnp.zeros_like(phi)
    return jnp.stack([zero, zero, phi, pin[0], pin[1], jnp.arctan2(c[1], c[0]), pivot[0], pivot[1],
                      jnp.arctan2(r[1], r[0])])


def four_bar(
    nx: int = 100,
    ny: int = 6,
    n_modes: int = 6,
    t1: float = 3.0,
    *,
    crank: float = 0.2,
    rocker: float = 0.8,
    ground: float = 0.9,
    speed: float = 4 * np.pi,
    t_ramp: float = 1.0,
    crank_mass: float = 0.5,
    rocker_mass: float = 1.5,
    length: float = 1.0,
    height: float = 0.06,
    thickness: float = 0.01,
    material: SIMP = SIMP(),
) -> Case:
    """A crank–rocker four-bar: rigid crank, flexible coupler (the design rod), rigid rocker.

    Bodies (in this order): the crank, a uniform bar of length `crank` pivoting about the inertial
    origin with its angle prescribed by the run-up law of paper eqs. 45–46 ([`RampLaw`][] to
    `speed` within `t_ramp`); the coupler, the rod of REFERENCE_CASE §1–2 whose A is pinned to the
    crank tip and B to the rocker tip; the rocker, a uniform bar of length `rocker` pivoting about
    `(ground, 0)`. Coordinates `y_r = (crank R, theta | rod R, theta, q | rocker R, theta)`,
    independent `y = q`, the nine rigid coordinates dependent (9 constraint equations). Newton
    starts from [`rigid_four_bar_position`][] on the branch assembled at `phi = 0`, so the
    linkage stays on it however many turns the crank makes. Initial state at rest, `phi = 0`,
    `q = 0`. The objective is the integral compliance of the coupler (paper eq. 49).

    The lengths must satisfy Grashof's condition with the crank the shortest link
    (`s + l <= p + q`), so that the crank turns fully.

    **Arguments:**
    - `nx`, `ny`, `n_modes`: coupler mesh and retained modes; `t1`: end time.
    - `crank`, `rocker`, `ground`: link lengths (the coupler length is `length`).
    - `speed`, `t_ramp`: crank run-up; `crank_mass`, `rocker_mass`: rigid link masses.
    - `length`, `height`, `thickness`, `material`: the coupler rod.

    **Returns:** a [`Case`][] whose design map designs the body `"coupler"` (scene body 1).
    """
    check_grashof(crank, length, rocker, ground)
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    body = rod_body(nx, ny, n_modes, length=length, height=height, thickness=thickness, material=material)
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    scene = Scene(
        bodies=(
            Body("crank", uniform_bar(crank_mass, crank)),
            Body("coupler", body.uniform_body_data()),
            Body("rocker", uniform_bar(rocker_mass, rocker)),
        ),
        constraints=(
            GroundRevolute(body=0, marker=0, point=(0.0, 0.0)),
            AngleDriver(body=0, angle=law),
            Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0),
            Revolute(body_i=1, marker_i=1, body_j=2, marker_j=1),
            GroundRevolute(body=2, marker=0, point=(ground, 0.0)),
        ),
    )
    guess = _four_bar_guess
    n_r = scene.n_coordinates
    y_r0 = jnp.zeros(n_r)
    rigid = tuple(range(3)) + (3, 4, 5) + tuple(range(n_r - 3, n_r))
    y_r0 = y_r0.at[np.asarray(rigid)].set(guess(0.0, jnp.zeros(n_modes), scene))
    partition = choose_partition(scene, 0.0, y_r0, prefer_dependent=rigid)
    if partition.dependent != rigid:
        raise ValueError(f"The four-bar's rigid coordinates {rigid} are not a regular dependent set at phi = 0.")
    problem = Problem(scene, t1, positions=y_r0, objective=Compliance(body=1), partition=partition,
                      dependent_guess=guess)
    return Case(problem=problem, design_map=DesignMap({"coupler": body}))
