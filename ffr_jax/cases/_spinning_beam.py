"""A flexible rod driven to spin about its end A at high speed (geometric stiffening)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._design.material import SIMP
from .._objective._compliance import Compliance
from .._dynamics._problem import Problem
from .._scene._angle_driver import AngleDriver
from .._scene._body import Body
from .._scene._ground_revolute import GroundRevolute
from .._scene._laws import ConstantSpeedLaw
from .._scene._scene import Scene
from .._scene._stiffening import GeometricStiffening
from ._rod import rod_body


def spinning_beam(
    nx: int = 100,
    ny: int = 6,
    n_modes: int = 6,
    t1: float = 0.5,
    *,
    speed: float = 100.0,
    perturbation: float = 1e-3,
    stiffening: bool = True,
    length: float = 1.0,
    height: float = 0.06,
    thickness: float = 0.01,
    material: SIMP = SIMP(),
) -> Case:
    """The rod of REFERENCE_CASE §1–2 spinning at constant angular speed about its pinned end A.

    A [`GroundRevolute`][] holds A at the inertial origin and an [`AngleDriver`][] prescribes the
    frame angle `theta = speed * t` (the frame's x-axis is the chord A–B, so the driver also holds
    B on the rotating radial line, transversally). The rod starts unstressed at `theta = 0`,
    already turning at `speed`, with a small transverse perturbation `q_1(0) = perturbation` of
    its first (bending) mode. With `stiffening` the scene holds a [`GeometricStiffening`][] of the
    rod, whose `K_geo(x)` [`Case.scene`][] recomputes for every design; without it the
    bending modes are softened by the rotation, with it they stiffen (Southwell).
    Coordinates `y_r = (R_x, R_y, theta, q)`, independent `y = q`, dependent `(R_x, R_y, theta)`.
    The objective is the integral compliance (paper eq. 49).

    **Arguments:**
    - `nx`, `ny`, `n_modes`: mesh and retained modes; `t1`: end time.
    - `speed`: the spin rate in rad/s; `perturbation`: initial modal amplitude of mode 1.
    - `stiffening`: include the geometric stiffening effect (static structure).
    - `length`, `height`, `thickness`, `material`: the rod.

    **Returns:** a [`Case`][].
    """
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    body = rod_body(nx, ny, n_modes, length=length, height=height, thickness=thickness, material=material)
    forces = (GeometricStiffening(body=0, modal_geometric_stiffness=jnp.zeros((n_modes, n_modes))),) if stiffening else ()
    scene = Scene(
        bodies=(Body("rod", body.uniform_body_data()),),
        constraints=(
            GroundRevolute(body=0, marker=0, point=(0.0, 0.0)),
            AngleDriver(body=0, angle=ConstantSpeedLaw(speed)),
        ),
        forces=forces,
    )
    y_r0 = jnp.zeros(scene.n_coordinates).at[3].set(float(perturbation))
    z_r0 = jnp.zeros(scene.n_coordinates).at[2].set(float(speed))
    problem = Problem(scene, t1, positions=y_r0, velocities=z_r0, objective=Compliance(body=0))
    case = Case(problem=problem, design_map=DesignMap({"rod": body}))
    # The template carries K_geo of the uniform design the template's body data belong to.
    if stiffening:
        case = eqx.tree_at(lambda c: c.problem.scene, case, case.scene(case.initial_design(0.5)))
    return case
