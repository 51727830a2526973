"""A spatial four-bar (RSSR) linkage of rigid spatial bodies: crank and rocker on skew ground hinges,
a coupler on two spherical joints."""

import functools

import jax.numpy as jnp
import numpy as np

from .._dynamics._model import Partition
from .._objective._kinetic_energy import KineticEnergy
from .._dynamics._problem import Problem
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


# Independent coordinates (crank e0, e3; coupler e0, e1; rocker e0): the crank angle with its gauge, the coupler's
# spin with its gauge, the rocker's gauge; every other coordinate follows from the joints. This is the partition
# the column-pivoted QR of the constraint Jacobian picks at the default assembly; [`_closed_form_guess`][] is
# written for it.
_INDEPENDENT = (3, 6, 10, 11, 17)


def _quaternion_product(a, b):
    return jnp.concatenate([a[:1] * b[:1] - a[1:] @ b[1:], a[0] * b[1:] + b[0] * a[1:] + jnp.cross(a[1:], b[1:])])


def _closed_form_guess(t, y, scene, *, branch: float):
    """The dependent coordinates of the assembled linkage from the independent ones, in closed form.

    Crank angle `phi = 2 atan2(e3, e0)` of the crank; rocker angle from `|P(phi) - Q(psi)| = b`, i.e.
    `D_y cos psi + D_z sin psi = (b^2 - |D|^2 - c^2) / (2 c)` with `D = P - B`, on the assembly branch `branch`
    (the sign of `psi - atan2(D_z, D_y)` at the start); the coupler's Euler parameters in the plane of the rotations
    taking its axis to `Q - P` (`q_min` and `q_min (0, 1, 0, 0)`, spin and gauge), fitted to its independent
    `(e0, e1)`; each body's gauge `|p|` from its independent entries. Newton's method then only polishes.
    """
    del t
    a = scene.bodies[0].data.marker_positions[1, 0]
    b = scene.bodies[1].data.marker_positions[1, 0]
    c = -scene.bodies[2].data.marker_positions[1, 1]
    hinge = scene.constraints[1].point
    crank_e0, crank_e3, coupler_e0, coupler_e1, rocker_e0 = y
    phi = 2.0 * jnp.arctan2(crank_e3, crank_e0)
    pin = jnp.stack([a * jnp.cos(phi), a * jnp.sin(phi), jnp.zeros_like(phi)])
    d = pin - hinge
    ratio = (b * b - d @ d - c * c) / (2.0 * c * jnp.hypot(d[1], d[2]))
    psi = jnp.arctan2(d[2], d[1]) + branch * jnp.arccos(jnp.clip(ratio, -1.0, 1.0))
    rocker_pin = hinge + c * jnp.stack([jnp.zeros_like(psi), -jnp.cos(psi), -jnp.sin(psi)])
    axis = (rocker_pin - pin) / b
    q_min = jnp.concatenate([1.0 + axis[:1], jnp.stack([jnp.zeros_like(phi), -axis[2], axis[1]])])
    q_min = q_min / jnp.linalg.norm(q_min)
    q_spin = _quaternion_product(q_min, jnp.array([0.0, 1.0, 0.0, 0.0]))
    alpha, beta = jnp.linalg.solve(jnp.stack([q_min[:2], q_spin[:2]], axis=1), jnp.stack([coupler_e0, coupler_e1]))
    coupler_p = alpha * q_min + beta * q_spin
    rocker_e1 = rocker_e0 * jnp.tan(0.5 * psi)
    zero = jnp.zeros_like(phi)
    return jnp.concatenate([jnp.zeros(3), jnp.stack([zero, zero]), pin, coupler_p[2:], hinge,
                            jnp.stack([rocker_e1, zero, zero])])


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
    partition = Partition(independent=_INDEPENDENT, dependent=tuple(i for i in range(21) if i not in _INDEPENDENT))
    d = pin - b_point
    branch = float(np.sign(np.angle(np.exp(1j * (psi0 - np.arctan2(d[2], d[1]))))))
    return Problem(scene, t1, positions=positions, velocities=velocities[list(_INDEPENDENT)], objective=KineticEnergy(),
                   partition=partition, dependent_guess=functools.partial(_closed_form_guess, branch=branch))
