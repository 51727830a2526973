"""A spatial four-bar (RSSR) linkage of rigid spatial bodies: crank and rocker on skew ground hinges,
a coupler on two spherical joints."""

import numpy as np

from .._model import choose_partition
from .._objective._kinetic_energy import KineticEnergy
from .._problem import Problem
from .._scene._body import Body
from .._scene._gravity import Gravity
from .._scene._scene import Scene
from .._spatial._body_data import SpatialBodyData, spatial_rigid_body_data
from .._spatial._euler_parameters import euler_parameter_rates, euler_parameters
from .._spatial._revolute import SpatialRevolute
from .._spatial._spherical import SphericalJoint


def _rod(mass: float, length: float, radius: float, direction) -> SpatialBodyData:
    """A slender cylinder from the body-frame origin along the unit body axis `direction` (markers: both ends)."""
    d = np.asarray(direction, dtype=float)
    s = mass * length / 2 * d
    axial, transverse = mass * radius**2 / 2, mass * length**2 / 12 + mass * radius**2 / 4
    j_g = transverse * np.eye(3) + (axial - transverse) * np.outer(d, d)
    j_origin = j_g + ((s @ s) * np.eye(3) - np.outer(s, s)) / mass  # parallel axes
    return spatial_rigid_body_data(mass, s, j_origin, [np.zeros(3), length * d])


def _rotation_between(u, v) -> np.ndarray:
    """Euler parameters of the smallest rotation taking the direction `u` to `v` (not opposite)."""
    u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
    p = np.concatenate([[1.0 + u @ v], np.cross(u, v)])
    return p / np.linalg.norm(p)


def spatial_four_bar(t1: float = 2.0, *, crank: float = 0.05, rocker: float = 0.15, coupler: float = 0.24,
                     rocker_hinge=(0.1, 0.2, 0.05), crank_speed: float = 10.0, gravity: float = 9.81,
                     masses=(0.5, 0.3, 0.4)) -> Problem:
    """An RSSR linkage moving freely under gravity from a spinning crank (a conservative motion).

    The crank turns about the inertial z axis through the origin, its pin at `crank` from the axis; the
    rocker about the x axis through `rocker_hinge`, its pin at `rocker`; the coupler of length `coupler`
    joins the pins by spherical joints. With the defaults every crank angle assembles (the coupler length
    lies between the largest least and the smallest greatest pin distance over a crank turn, 0.164..0.322),
    so the crank turns fully. Degrees of freedom: the crank angle and the coupler's spin about its own axis
    (besides the gauge direction of each body's Euler parameters). Assembled at crank angle 0 with the rocker
    on the branch `psi in (-pi/2, pi/2)`; the crank starts at `crank_speed` about z, the rest at rest
    (dependent velocities from the constraints).

    **Arguments:**
    - `t1`: end time; `crank`, `rocker`, `coupler`: link lengths; `rocker_hinge`: `(3,)` rocker hinge point.
    - `crank_speed`: initial crank rate [rad/s]; `gravity`: along `-z`; `masses`: of crank, coupler, rocker.

    **Returns:** a [`Problem`][] (objective: the kinetic energy integral).
    """
    b_point = np.asarray(rocker_hinge, dtype=float)
    pin = np.array([crank, 0.0, 0.0])

    def rocker_pin(psi):
        return b_point + rocker * np.array([0.0, -np.cos(psi), -np.sin(psi)])

    psis = np.linspace(-np.pi / 2, np.pi / 2, 20001)
    gap = np.array([np.linalg.norm(pin - rocker_pin(s)) for s in psis]) - coupler
    crossing = np.flatnonzero(np.diff(np.sign(gap)) != 0)
    if crossing.size == 0:
        raise ValueError(f"The spatial four-bar cannot assemble at crank angle 0: no rocker angle in (-pi/2, pi/2) puts "
                         f"the pins {coupler} apart. Change the link lengths or the rocker hinge.")
    k = crossing[0]
    psi0 = psis[k] - gap[k] * (psis[k + 1] - psis[k]) / (gap[k + 1] - gap[k])
    bodies = (Body("crank", _rod(masses[0], crank, 0.01, (1.0, 0.0, 0.0))),
              Body("coupler", _rod(masses[1], coupler, 0.005, (1.0, 0.0, 0.0))),
              Body("rocker", _rod(masses[2], rocker, 0.01, (0.0, -1.0, 0.0))))
    constraints = (SpatialRevolute(0, 0, (0.0, 0.0, 1.0)), SpatialRevolute(2, 0, (1.0, 0.0, 0.0), point=b_point),
                   SphericalJoint(1, 0, 0, 1), SphericalJoint(1, 1, 2, 1))
    scene = Scene(bodies=bodies, constraints=constraints, forces=(Gravity((0.0, 0.0, -gravity)),))
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    positions = np.concatenate([np.zeros(3), identity, pin, _rotation_between(np.array([1.0, 0.0, 0.0]),
                                rocker_pin(psi0) - pin), b_point, euler_parameters((1.0, 0.0, 0.0), psi0)])
    velocities = np.zeros(21)
    velocities[3:7] = np.asarray(euler_parameter_rates(identity, [0.0, 0.0, crank_speed]))
    partition = choose_partition(scene, 0.0, positions, prefer_dependent=tuple(o + k for o in scene.offsets for k in range(3)))
    return Problem(scene, t1, positions=positions, velocities=velocities[list(partition.independent)],
                   objective=KineticEnergy(), partition=partition)
