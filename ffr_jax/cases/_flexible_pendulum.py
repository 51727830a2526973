"""A flexible rod swinging about a ground pivot under gravity (an open tree, no kinematic loop)."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._design.material import SIMP
from .._objective._compliance import Compliance
from .._dynamics._problem import Problem
from .._scene._body import Body
from .._scene._damping import ModalDamping
from .._scene._gravity import Gravity
from .._scene._ground_revolute import GroundRevolute
from .._scene._scene import Scene
from ._rod import rod_body


def flexible_pendulum(
    nx: int = 100,
    ny: int = 6,
    n_modes: int = 6,
    t1: float = 2.0,
    *,
    gravity: bool = True,
    initial_angle: float = -np.pi / 4,
    damping_ratio: float | None = None,
    g: float = 9.81,
    length: float = 1.0,
    height: float = 0.06,
    thickness: float = 0.01,
    material: SIMP = SIMP(),
) -> Case:
    """A flexible rod pinned at its point A to the ground, released from rest at `initial_angle`.

    The rod is the one of REFERENCE_CASE §1–2 (Q4 mesh, SIMP design, hinged–hinged modes, frame
    origin at A with the x-axis through B). A `GroundRevolute` keeps A at the inertial origin;
    with `gravity` the rod swings under `g = (0, -g)`. Coordinates `y_r = (R_x, R_y, theta, q)`,
    independent `y = (theta, q)`, dependent `(R_x, R_y)` (exactly zero, since A has no elastic
    displacement). Initial state: `R = 0`, `theta = initial_angle` (`-pi/2` hangs straight down),
    `q = 0`, at rest. The objective is the integral compliance (paper eq. 49).

    **Arguments:**
    - `nx`, `ny`: mesh of the rod; `n_modes`: retained modes; `t1`: end time.
    - `gravity`: add [`Gravity`][] (a static choice: without it the scene holds no gravity at all).
    - `initial_angle`: `theta(0)` in rad, measured from the inertial x-axis.
    - `damping_ratio`: if given, [`ModalDamping`][] of the rod with this ratio.
    - `g`: magnitude of the gravitational acceleration; `length`, `height`, `thickness`: rod.
    - `material`: the SIMP law.

    **Returns:** a [`Case`][].
    """
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    body = rod_body(nx, ny, n_modes, length=length, height=height, thickness=thickness, material=material)
    forces = ()
    if gravity:
        forces += (Gravity((0.0, -float(g))),)
    if damping_ratio is not None:
        forces += (ModalDamping(body=0, ratio=damping_ratio),)
    scene = Scene(
        bodies=(Body("rod", body.uniform_body_data()),),
        constraints=(GroundRevolute(body=0, marker=0, point=(0.0, 0.0)),),
        forces=forces,
    )
    y_r0 = jnp.zeros(scene.n_coordinates).at[2].set(float(initial_angle))
    problem = Problem(scene, t1, positions=y_r0, objective=Compliance(body=0))
    return Case(problem=problem, design_map=DesignMap({"rod": body}))
