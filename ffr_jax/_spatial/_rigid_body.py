"""Equations of motion of one free rigid spatial body in Euler parameters (paper eq. 8, no modes).

Body coordinates `y_b = (R, p)` (7: position of the frame origin and Euler parameters) and velocities
`z_b = dy_b/dt = (Rdot, pdot)`, so the kinematic matrix of paper eq. 6 is the identity in these
velocities, as for a planar body, and the minimal-coordinate model needs no change. The rotation
`A(p / |p|)` depends on the direction of `p` only. With `n = |p|`, `u = p / n`, `H = G(u) / n`
(`G` of `_euler_parameters`), `omega' = 2 H pdot` and `rho = u . pdot` (the radial rate, which does
not move the body):

`omega'dot = 2 H pddot - 2 (rho / n) omega'`,

and the virtual work `int delta r . rddot dm` with `r = R + A u`, `delta pi' = 2 H delta p`, gives
`M_b zdot_b + h_omega = h_a` with (`s` first moment, `J` inertia about the frame origin)

- `M_RR = m I`, `M_Rp = -2 A s~ H`, `M_pp = 4 H^T J H + k u u^T`,
- `h_omega,R = A (omega'~ omega'~ s + 2 (rho / n) s~ omega')`,
- `h_omega,p = 2 H^T (omega'~ J omega' - 2 (rho / n) J omega') + k u (|pdot|^2 - rho^2) / n`.

The terms in `k` fix the radial direction, which carries no kinetic energy: they make `M_b` positive
definite and give `rhodot = 0`, so `|p|` stays constant along the exact motion (and the solver's
drift of `|p|` is harmless). They are the Lagrange equations of `T + 1/2 k rho^2`; `k = 4 tr(J) / 3`
puts them on the scale of the rotational block.

**Why not the normalisation `|p|^2 = 1` as a constraint equation.** With a fixed coordinate partition
one Euler parameter would be dependent; every fixed linear combination of Euler parameters passes
through zero on a body that keeps turning (for a top, `e0 = cos(theta/2) cos((phi + psi)/2)`), where the
partition is singular. Removing the radial direction as above keeps all four parameters independent,
costs one extra state per body, and is free of singularities.
"""

import jax.numpy as jnp

from ._body_data import SpatialBodyData
from ._euler_parameters import kinematic_matrix, rotation_matrix, skew, unit


def _regularisation(data: SpatialBodyData):
    return 4.0 * jnp.trace(data.inertia) / 3.0


def _kinematics(y_b, z_b):
    """`(A, H, u, n, omega', rho)` of body coordinates and velocities."""
    p, pdot = y_b[3:7], z_b[3:7]
    u, n = unit(p)
    h = kinematic_matrix(u) / n
    return rotation_matrix(p), h, u, n, 2.0 * h @ pdot, u @ pdot


def mass_matrix(data: SpatialBodyData, y_b):
    """`M_b(y_b)` `(7, 7)`, symmetric positive definite."""
    p = y_b[3:7]
    u, n = unit(p)
    h = kinematic_matrix(u) / n
    a = rotation_matrix(p)
    m_rr = data.mass * jnp.eye(3, dtype=a.dtype)
    m_rp = -2.0 * a @ skew(data.first_moment) @ h
    m_pp = 4.0 * h.T @ data.inertia @ h + _regularisation(data) * jnp.outer(u, u)
    return jnp.concatenate([jnp.concatenate([m_rr, m_rp], axis=1), jnp.concatenate([m_rp.T, m_pp], axis=1)], axis=0)


def inertia_forces(data: SpatialBodyData, y_b, z_b):
    """`-h_omega`: the quadratic-velocity (centrifugal, gyroscopic) forces `(7,)`."""
    a, h, u, n, omega, rho = _kinematics(y_b, z_b)
    pdot = z_b[3:7]
    s, j = data.first_moment, data.inertia
    w = skew(omega)
    h_r = a @ (w @ (w @ s) + 2.0 * (rho / n) * (skew(s) @ omega))
    h_p = 2.0 * h.T @ (w @ (j @ omega) - 2.0 * (rho / n) * (j @ omega)) + _regularisation(data) * u * (
        (pdot @ pdot - rho * rho) / n)
    return -jnp.concatenate([h_r, h_p])


def marker_position(data: SpatialBodyData, marker: int, y_b):
    """Inertial position `r_P = R + A(p) u_P` of body marker `marker`."""
    return y_b[:3] + rotation_matrix(y_b[3:7]) @ data.marker_positions[marker]


def body_axis(y_b, axis_body):
    """The inertial direction `A(p) a` of a body-frame vector `a`."""
    return rotation_matrix(y_b[3:7]) @ axis_body


def kinetic_energy(data: SpatialBodyData, y_b, z_b):
    """`T = 1/2 m |Rdot|^2 + Rdot . A (omega' x s) + 1/2 omega'^T J omega'` (the radial rate carries none)."""
    a, _, _, _, omega, _ = _kinematics(y_b, z_b)
    rdot = z_b[:3]
    return 0.5 * data.mass * rdot @ rdot + rdot @ (a @ jnp.cross(omega, data.first_moment)) + 0.5 * omega @ (
        data.inertia @ omega)


def gravity_potential(data: SpatialBodyData, acceleration, y_b):
    """`V = -g . (m R + A s)`."""
    return -acceleration @ (data.mass * y_b[:3] + rotation_matrix(y_b[3:7]) @ data.first_moment)


def gravity_force(data: SpatialBodyData, acceleration, y_b):
    """`Q = -dV/dy_b` of [`gravity_potential`][] `(7,)`: `Q_R = m g`, `Q_p = 2 H^T s~ A^T g`.

    (`delta(A s) = A (delta pi' x s) = -A s~ 2 H delta p`; written out rather than differentiated, so that the
    sensitivity methods, which differentiate the forces again, see no nested derivative.)
    """
    p = y_b[3:7]
    u, n = unit(p)
    h = kinematic_matrix(u) / n
    q_p = 2.0 * h.T @ (skew(data.first_moment) @ (rotation_matrix(p).T @ acceleration))
    return jnp.concatenate([data.mass * acceleration, q_p])


def momenta(data: SpatialBodyData, y_b, z_b):
    """Linear momentum `L = m Rdot + A (omega' x s)` and angular momentum about the inertial origin
    `H_O = R x L + A s x Rdot + A J omega'` (`int r x rdot dm` with `r = R + A u`), each `(3,)`."""
    a, _, _, _, omega, _ = _kinematics(y_b, z_b)
    r, rdot = y_b[:3], z_b[:3]
    lin = data.mass * rdot + a @ jnp.cross(omega, data.first_moment)
    ang = jnp.cross(r, lin) + jnp.cross(a @ data.first_moment, rdot) + a @ (data.inertia @ omega)
    return lin, ang
