"""The flexible slider–crank of the paper (Sect. 4), exactly as fixed in REFERENCE_CASE.md."""

import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._design.designed_body import DesignedBody
from .._design.material import SIMP
from .._design.modal.auto import AutoModes
from .._design.modal.base import AbstractModalSolver
from .._checks import integer, number, positive
from .._objective._compliance import Compliance
from .._dynamics._problem import Problem
from .._scene._body import Body
from .._scene._laws import RampLaw
from .._scene._point_on_line import PointOnLine
from .._scene._prescribed_point import CrankPin
from .._scene._scene import Scene
from ._rod import rod_body
from ._spatial_slider_crank import spatial_slider_crank_problem


def slider_crank_guess(t, y, scene):
    """Rigid-body estimate of `(R_x, R_y, theta)`: `R = P(t)`, `sin theta = -P_y / l`.

    The rod length `l` is read from the scene (the undeformed position of B, marker 1), so the
    estimate holds for every member of the family.
    """
    del y
    pin = scene.constraints[0].pin(t)
    length = scene.bodies[0].data.marker_positions[1, 0]
    return jnp.stack([pin[0], pin[1], -jnp.arcsin(pin[1] / length)])


def _check_eccentricity(eccentricity: float, length: float) -> None:
    if not 0 < number(eccentricity, "slider_crank(eccentricity=...)") < length:
        raise ValueError(
            f"The crank eccentricity must lie in (0, l) = (0, {length}) for the slider–crank to assemble "
            f"at every crank angle, got {eccentricity}."
        )


def slider_crank(
    nx: int = 100,
    ny: int = 6,
    n_modes: int = 6,
    t1: float = 3.0,
    *,
    eccentricity: float = 0.1,
    speed: float = 12 * np.pi,
    t_ramp: float = 2.0,
    length: float = 1.0,
    height: float = 0.06,
    thickness: float = 0.01,
    material: SIMP = SIMP(),
    modal_solver: AbstractModalSolver = AutoModes(),
    rod: DesignedBody | None = None,
    spatial: bool = False,
) -> Case:
    """The flexible slider–crank (REFERENCE_CASE.md, paper Sect. 4) and its family of small variants.

    A rigid crank of eccentricity `eps` turns about the inertial origin with the prescribed angle
    of paper eqs. 45–46 (run-up to `speed` within `t_ramp`, then constant speed; the angle at
    `t_ramp` is `speed * t_ramp / 2`, i.e. `12 pi` for the reference). The rod's point A follows the
    crank pin; point B slides on the inertial x-axis. Coordinates `y_r = (R_x, R_y, theta, q)`,
    independent `y = q`, dependent `(R_x, R_y, theta)`, initial state at rest with
    `R = (eps, 0)`, `theta = 0`, `q = 0`. The objective is the integral compliance (eq. 49).

    **Arguments:**
    - `nx`, `ny`: mesh of the rod (`ny` even, `nx >= 4`); `n_modes`: retained modes; `t1`: end time.
    - `eccentricity`, `speed`, `t_ramp`: crank; `length`, `height`, `thickness`: rod.
    - `material`: the SIMP law (defaults of REFERENCE_CASE §1).
    - `modal_solver`: [`AutoModes`][] (default: Lanczos above 1,000 degrees of freedom, i.e. the
      reference 100 x 6 rod and up to 1000 x 100 and beyond), [`DenseModes`][] or
      [`LanczosModes`][]; all give the same numbers. Forward mode (`jax.jvp`) with respect to `x`
      needs `DenseModes()`.
    - `rod`: another designed connecting rod (e.g. the rod read from a mesh file, or any body whose
      marker 0 is the crank pin A and marker 1 the slider point B, both on the frame's x-axis);
      default [`rod_body`][]`(nx, ny, n_modes, ...)` with the arguments above.
    - `spatial`: build the same mechanism from spatial bodies and joints (issue 26): the rod's design lifted to
      3D (nodes at `z = 0`, [`SpatialFlexibleBodyData`][]), a rigid spatial crank on a ground hinge about `z`
      with the same driven angle, hinged to the rod at A, and B on the plane `y = 0`; the rod's coordinates are
      `(R, p, q)` (Euler parameters), independent `q` as in the planar case, and `psi` and its gradient are the
      planar case's (`ffr_jax.cases._spatial_slider_crank`).

    **Returns:** a [`Case`][]: the [`Problem`][] with the rod's compliance as objective and a
    [`DesignMap`][] of the rod (`case.design` is its [`DesignedBody`][], see [`rod_body`][]).
    """
    # Every number is checked before anything is computed (the rod's modes compile first).
    if not isinstance(spatial, bool):
        raise ValueError(f"slider_crank(spatial=...) must be True or False, got {spatial!r}.")
    t1 = positive(t1, "slider_crank(t1=...)", "It is the end time in s.")
    t_ramp = positive(t_ramp, "slider_crank(t_ramp=...)", "It is the run-up time of the crank in s.")
    speed = number(speed, "slider_crank(speed=...)")
    if rod is None:
        for name, value in (("nx", nx), ("ny", ny), ("n_modes", n_modes)):
            integer(value, f"slider_crank({name}=...)", 1)
        length = positive(length, "slider_crank(length=...)")
        positive(height, "slider_crank(height=...)")
        positive(thickness, "slider_crank(thickness=...)")
        if not isinstance(material, SIMP):
            raise ValueError(f"material must be an ffr_jax.SIMP, got {type(material).__name__}.")
        _check_eccentricity(eccentricity, length)
    body = rod if rod is not None else rod_body(nx, ny, n_modes, length=length, height=height,
                                                thickness=thickness, material=material, modal_solver=modal_solver)
    rod = Body("rod", body.uniform_body_data())
    _check_eccentricity(eccentricity, float(rod.data.marker_positions[1, 0]))
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    if spatial:
        return Case(problem=spatial_slider_crank_problem(body, eccentricity, law, t1),
                    design_map=DesignMap({"rod": body}))
    scene = Scene(
        bodies=(rod,),
        constraints=(
            CrankPin(body=0, marker=0, radius=eccentricity, angle=law),
            PointOnLine(body=0, marker=1, point=(0.0, 0.0), direction=(1.0, 0.0)),
        ),
    )
    y_r0 = jnp.zeros(scene.n_coordinates).at[0].set(eccentricity)
    problem = Problem(scene, t1, positions=y_r0, objective=Compliance(body=0), dependent_guess=slider_crank_guess)
    return Case(problem=problem, design_map=DesignMap({"rod": body}))
