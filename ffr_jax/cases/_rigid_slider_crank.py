"""A rigid slider–crank with a massive slider held by a spring–damper."""

import jax.numpy as jnp
import numpy as np

from .._scene._body_data import rigid_body_data
from .._dynamics._model import Partition, choose_partition
from .._objective._base import AbstractIntegrand
from .._objective._kinetic_energy import KineticEnergy
from .._dynamics._problem import Problem
from .._scene._angle_driver import AngleDriver
from .._scene._body import Body
from .._scene._ground_revolute import GroundRevolute
from .._scene._laws import ConstantSpeedLaw, RampLaw
from .._scene._point_on_line import PointOnLine
from .._scene._revolute import Revolute
from .._scene._scene import Scene
from .._scene._spring_damper import SpringDamper


def slider_position(phi, *, eccentricity, length):
    """Closed-form slider kinematics `x_B = eps cos phi + sqrt(l^2 - eps^2 sin^2 phi)`."""
    return eccentricity * jnp.cos(phi) + jnp.sqrt(length**2 - (eccentricity * jnp.sin(phi)) ** 2)


def _rigid_slider_crank_guess(t, y, scene, *, driven: bool):
    """Closed-form positions of all dependent coordinates from the crank angle (geometry from the scene)."""
    phi = scene.constraints[-1].angle(t) if driven else y[0]
    eps = scene.bodies[0].data.marker_positions[1, 0]
    length = scene.bodies[1].data.marker_positions[1, 0]
    pin = eps * jnp.stack([jnp.cos(phi), jnp.sin(phi)])
    x_b = slider_position(phi, eccentricity=eps, length=length)
    zero = jnp.zeros_like(phi)
    full = jnp.stack([zero, zero, phi, pin[0], pin[1], -jnp.arcsin(pin[1] / length), x_b, zero, zero])
    dependent = (0, 1, 2, 3, 4, 5, 6, 7, 8) if driven else (0, 1, 3, 4, 5, 6, 7, 8)
    return full[np.asarray(dependent)]


def _driven_guess(t, y, scene):
    return _rigid_slider_crank_guess(t, y, scene, driven=True)


def _free_guess(t, y, scene):
    return _rigid_slider_crank_guess(t, y, scene, driven=False)


def rigid_slider_crank(
    t1: float = 1.0,
    *,
    driven: bool = True,
    eccentricity: float = 0.1,
    length: float = 0.4,
    crank_mass: float = 0.5,
    rod_mass: float = 1.0,
    slider_mass: float = 2.0,
    stiffness: float = 2.0e3,
    damping: float = 0.0,
    rest_length: float = 0.4,
    spring_anchor: float = 0.0,
    speed: float = 4 * np.pi,
    t_ramp: float = 0.5,
    initial_speed: float = 10.0,
    partition: Partition | None = None,
    objective: AbstractIntegrand | None = None,
) -> Problem:
    """A slider–crank of rigid bodies: crank, connecting rod, and a slider of mass `m_s` on the x-axis.

    Bodies: the crank, a uniform bar of length `eps` (frame at the pivot, the inertial origin);
    the connecting rod, a uniform bar of length `l` (frame at the crank pin A, marker 1 at B); the
    slider, a block of mass `slider_mass` with its frame at B, kept on the x-axis by a
    [`PointOnLine`][] and from turning by an [`AngleDriver`][] at zero angle (a prismatic guide).
    A [`SpringDamper`][] pulls the slider towards the ground point `(spring_anchor, 0)`.
    Coordinates `y_r = (crank R, theta | rod R, theta | slider R, theta)`.

    - `driven=True`: the crank angle follows the run-up law [`RampLaw`][] (paper eqs. 45–46, to
      `speed` within `t_ramp`): the mechanism has no degree of freedom left, every coordinate is
      dependent and the motion is pure kinematics, `x_B = eps cos phi + sqrt(l^2 - eps^2 sin^2 phi)`
      (the slider mass and spring only change the driving torque).
    - `driven=False`: the crank turns freely, starting at `phi = 0` with angular speed
      `initial_speed`; the crank angle is the one independent coordinate and the spring–damper
      drives the dynamics.

    **Arguments:**
    - `t1`: end time; `eccentricity`, `length`: crank radius `eps` and rod length `l` (`eps < l`).
    - `crank_mass`, `rod_mass`, `slider_mass`: the rigid bodies' masses.
    - `stiffness`, `damping`, `rest_length`, `spring_anchor`: the spring–damper.
    - `partition`: override the coordinate partition (default: the crank angle independent when
      free, nothing independent when driven).
    - `objective`: the objective (default: the integral of the kinetic energy, `int T dt`).

    **Returns:** a [`Problem`][].
    """
    if not 0 < eccentricity < length:
        raise ValueError(
            f"The crank eccentricity must lie in (0, l) = (0, {length}) for the slider–crank to assemble "
            f"at every crank angle, got {eccentricity}."
        )
    if t1 <= 0:
        raise ValueError(f"t1 must be positive, got {t1}.")
    law = RampLaw(t_ramp=t_ramp, angle_at_ramp=speed * t_ramp / 2, speed=speed)
    constraints = (
        GroundRevolute(body=0, marker=0, point=(0.0, 0.0)),
        Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0),
        Revolute(body_i=1, marker_i=1, body_j=2, marker_j=0),
        PointOnLine(body=2, marker=0, point=(0.0, 0.0), direction=(1.0, 0.0)),
        AngleDriver(body=2, angle=ConstantSpeedLaw(0.0)),
    )
    if driven:
        constraints += (AngleDriver(body=0, angle=law),)
    scene = Scene(
        bodies=(
            Body("crank", rigid_body_data(crank_mass, (0.5 * crank_mass * eccentricity, 0.0),
                                          crank_mass * eccentricity**2 / 3.0, [[0.0, 0.0], [eccentricity, 0.0]])),
            Body("rod", rigid_body_data(rod_mass, (0.5 * rod_mass * length, 0.0), rod_mass * length**2 / 3.0,
                                        [[0.0, 0.0], [length, 0.0]])),
            Body("slider", rigid_body_data(slider_mass, (0.0, 0.0), slider_mass * 1e-3, [[0.0, 0.0]])),
        ),
        constraints=constraints,
        forces=(SpringDamper(2, 0, stiffness=stiffness, damping=damping, rest_length=rest_length,
                             ground_point=(spring_anchor, 0.0)),),
    )
    y_r0 = jnp.array([0.0, 0.0, 0.0, eccentricity, 0.0, 0.0, eccentricity + length, 0.0, 0.0])
    z_r0 = jnp.zeros(9)
    if not driven:
        # Crank turning at `initial_speed` about the origin; the rod's and slider's velocities follow.
        w = float(initial_speed)
        z_r0 = jnp.array([0.0, 0.0, w, 0.0, w * eccentricity, -w * eccentricity / length, 0.0, 0.0, 0.0])
    if partition is None:
        partition = choose_partition(scene, 0.0, y_r0, prefer_dependent=(0, 1, 3, 4, 5, 6, 7, 8, 2))
    guess = _driven_guess if driven else _free_guess
    default = partition.dependent == ((0, 1, 2, 3, 4, 5, 6, 7, 8) if driven else (0, 1, 3, 4, 5, 6, 7, 8))
    return Problem(scene, t1, positions=y_r0, velocities=z_r0, partition=partition,
                   objective=KineticEnergy() if objective is None else objective,
                   dependent_guess=guess if default else None)
