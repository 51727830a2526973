"""A crank–rocker four-bar whose coupler is a designed link with two pin holes (meshed with gmsh)."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.assembly import FEModel
from .._design.design_map import DesignMap
from .._design.designed_body import DesignedBody
from .._design.element.base import AbstractElement
from .._design.element.qm6 import QM6
from .._design.geometry import LinkMesh, link_with_holes
from .._design.material import SIMP
from .._design.modal.auto import AutoModes
from .._design.modal.base import AbstractModalSolver
from .._design.modal.interface import Interface
from .._design.modal.reduction import ModalReduction
from .._design.modal.reference import Clamped
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


def link_body(link: LinkMesh, n_modes: int = 4, *, thickness: float = 0.005, poisson: float = 0.3,
              element: AbstractElement = QM6(), material: SIMP = SIMP(),
              modal_solver: AbstractModalSolver = AutoModes()) -> DesignedBody:
    """The link with two pin holes as a designed body: its rims passive solid, a Craig–Bampton basis.

    Reference conditions: the rim of hole A clamped (the body frame moves with it); hole B's rim a
    rigid [`Interface`][] (a pin in a solid bushing: three static modes, its two translations and
    its rotation); plus `n_modes` fixed-interface eigenmodes. Markers: the centroids of the two
    rims (the pin centres), marker 0 at A, marker 1 at B.

    **Arguments:**
    - `link`: the [`LinkMesh`][] (e.g. from [`link_with_holes`][]); `n_modes`: eigenmodes.
    - `thickness`, `poisson`, `element` (default [`QM6`][], which does not lock in bending),
      `material`: the FE model; `modal_solver`: the modal solver.

    **Returns:** a [`DesignedBody`][] with `n_modes + 3` shape vectors.
    """
    model = FEModel(link.mesh, element, thickness, poisson)
    reduction = ModalReduction(n_modes, Clamped(link.rims[0]), interfaces=(Interface(link.rims[1], rigid=True),),
                               solver=modal_solver)
    return DesignedBody(model, link.domain, material, reduction, (link.rims[0], link.rims[1]))


def _link_four_bar_guess(t, y, scene):
    """Rigid-body estimate of the dependent coordinates (crank, coupler frame, rocker) on the assembled branch.

    The coupler's markers A and B sit at `c_A + u_A`, `c_B + u_B` in its frame (`u = Phi(c) q`),
    so the chord between them is `b = c_B + u_B - c_A - u_A` in the frame: its length closes the
    rigid four-bar, and the frame angle is the chord angle minus the angle of `b`.
    """
    phi = scene.constraints[1].angle(t)
    crank, link, rocker = (body.data for body in scene.bodies)
    pivot = scene.constraints[4].point
    marker_a = link.marker_positions[0] + link.marker_modes[0] @ y
    chord_body = link.marker_positions[1] + link.marker_modes[1] @ y - marker_a
    chord = jnp.sqrt(chord_body @ chord_body)
    pin, tip = rigid_four_bar_position(phi, chord, crank.marker_positions[1, 0], rocker.marker_positions[1, 0], pivot)
    c, r = tip - pin, tip - pivot
    theta = jnp.arctan2(c[1], c[0]) - jnp.arctan2(chord_body[1], chord_body[0])
    rotation = jnp.array([[jnp.cos(theta), -jnp.sin(theta)], [jnp.sin(theta), jnp.cos(theta)]])
    origin = pin - rotation @ marker_a
    zero = jnp.zeros_like(phi)
    return jnp.stack([zero, zero, phi, origin[0], origin[1], theta, pivot[0], pivot[1], jnp.arctan2(r[1], r[0])])


def link_four_bar(
    t1: float = 0.3,
    *,
    mesh_size: float = 0.004,
    n_modes: int = 4,
    length: float = 0.2,
    width: float = 0.05,
    hole_radius: float = 0.008,
    rim_width: float = 0.005,
    thickness: float = 0.005,
    element: AbstractElement = QM6(),
    material: SIMP = SIMP(),
    modal_solver: AbstractModalSolver = AutoModes(),
    crank: float = 0.05,
    rocker: float = 0.16,
    ground: float = 0.18,
    speed: float = 8 * np.pi,
    t_ramp: float = 0.2,
    crank_mass: float = 0.1,
    rocker_mass: float = 0.4,
    dt0: float = 1e-5,
) -> Case:
    """A crank–rocker four-bar: rigid crank, the holed link as a designed coupler, rigid rocker.

    Bodies (in this order): `"crank"`, a uniform bar of length `crank` turning about the inertial
    origin with the run-up law of paper eqs. 45–46 ([`RampLaw`][] to `speed` within `t_ramp`);
    `"coupler"`, the link of [`link_with_holes`][] (rounded ends, pin holes of `hole_radius` at
    distance `length`, a passive solid rim of `rim_width` around each) as a [`link_body`][]
    (hole A clamped, hole B a rigid Craig–Bampton interface, `n_modes` eigenmodes), pinned at A to
    the crank tip and at B to the rocker tip; `"rocker"`, a uniform bar of length `rocker`
    turning about `(ground, 0)`. The independent coordinates are the coupler's `n_modes + 3`
    elastic coordinates; the nine rigid coordinates are dependent (9 constraint equations),
    Newton starting from the rigid four-bar on the branch assembled at `phi = 0`. Initial state
    at rest, `phi = 0`, `q = 0`. The objective is the integral compliance of the coupler
    (paper eq. 49, with the static modes' stiffness included). The design variables are the
    densities of the link's elements outside the rims.

    **Arguments:**
    - `t1`: end time; `mesh_size`: gmsh target element size (`0.004`: 810 elements, 738 design
      variables; `0.005`: 522 and 456).
    - `n_modes`: eigenmodes of the coupler; `length`, `width`, `hole_radius`, `rim_width`: its
      geometry; `thickness`, `element`, `material`, `modal_solver`: its FE model.
    - `crank`, `rocker`, `ground`: link lengths (the coupler length is `length`; Grashof's
      condition with the crank shortest is checked); `crank_mass`, `rocker_mass`: rigid links.
    - `speed`, `t_ramp`: the crank run-up.
    - `dt0`: the first step of every solve (the link's interface modes reach several kHz: a first
      trial step of diffrax's default 0.01 s lies far outside Dopri8's stability region; see
      [`Problem`][]).

    **Returns:** a [`Case`][] designing the body `"coupler"`.
    """
    check_grashof(crank, length, rocker, ground)
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    link = link_with_holes(length=length, width=width, hole_radius=hole_radius, rim_width=rim_width,
                           mesh_size=mesh_size)
    body = link_body(link, n_modes, thickness=thickness, element=element, material=material,
                     modal_solver=modal_solver)
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
    n_q = scene.bodies[1].data.n_modes
    n_r = scene.n_coordinates
    rigid = (0, 1, 2, 3, 4, 5) + tuple(range(n_r - 3, n_r))
    y_r0 = jnp.zeros(n_r).at[np.asarray(rigid)].set(_link_four_bar_guess(0.0, jnp.zeros(n_q), scene))
    partition = choose_partition(scene, 0.0, y_r0, prefer_dependent=rigid)
    if partition.dependent != rigid:
        raise ValueError(f"The four-bar's rigid coordinates {rigid} are not a regular dependent set at phi = 0.")
    problem = Problem(scene, t1, positions=y_r0, objective=Compliance(body=1), partition=partition,
                      dependent_guess=_link_four_bar_guess, dt0=dt0)
    return Case(problem=problem, design_map=DesignMap({"coupler": body}))
