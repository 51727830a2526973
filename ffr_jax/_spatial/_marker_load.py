"""Velocity of a spatial body's marker and the generalized force of a force and torque acting there.

A marker `P` of a spatial body (rigid: no `q`) sits at `r_P = R + A(p) u_P`, `u_P = c_P + Phi_P q`, and its frame is
turned by `A(p) (I + (Psi_P q)~)`. A virtual displacement `delta y_b = (delta R, delta p, delta q)` moves and turns it
by (`delta pi' = 2 H delta p`, `H = G(p / |p|) / |p|` of `_rigid_body`)

- `delta r_P = delta R + A (delta pi' x u_P) + A Phi_P delta q`,
- `delta phi_P = A (delta pi' + Psi_P delta q)` (inertial; to first order in the small elastic rotation, as in the
  joints),

so the virtual work `F . delta r_P + tau . delta phi_P` of an inertial force `F` and torque `tau` at `P` is
`Q . delta y_b` with

`Q_R = F`, `Q_p = 2 H^T (u_P~ A^T F + A^T tau)`, `Q_q = Phi_P^T A^T F + Psi_P^T A^T tau`

(`F . A (delta pi' x u) = delta pi' . (u x A^T F)`). Written out rather than differentiated, as gravity is, so that
the sensitivity methods, which differentiate the forces again, see no nested derivative.
"""

import jax.numpy as jnp

from ._euler_parameters import kinematic_matrix, rotation_matrix, skew, unit
from ._flexible_body_data import SpatialFlexibleBodyData


def _marker_point(data, marker: int, y_b):
    """`u_P` (body frame) and, for a flexible body, `(Phi_P, Psi_P)`."""
    if isinstance(data, SpatialFlexibleBodyData):
        phi, psi = data.marker_modes[marker], data.marker_rotations[marker]
        return data.marker_positions[marker] + phi @ y_b[7:], phi, psi
    return data.marker_positions[marker], None, None


def marker_velocity(data, marker: int, y_b, z_b):
    """`rdot_P = Rdot + A (omega' x u_P + Phi_P qdot)` `(3,)` with `omega' = 2 H pdot`."""
    p = y_b[3:7]
    u, n = unit(p)
    omega = 2.0 * (kinematic_matrix(u) / n) @ z_b[3:7]
    u_p, phi, _ = _marker_point(data, marker, y_b)
    local = jnp.cross(omega, u_p)
    if phi is not None:
        local = local + phi @ z_b[7:]
    return z_b[:3] + rotation_matrix(p) @ local


def marker_load(data, marker: int, y_b, force, torque):
    """The generalized force `Q_b` `(7,)` or `(7 + n_q,)` of an inertial force `force` and torque `torque` `(3,)` at
    marker `marker` (the module docstring gives the virtual work)."""
    p = y_b[3:7]
    u, n = unit(p)
    h = kinematic_matrix(u) / n
    a = rotation_matrix(p)
    f_body, tau_body = a.T @ force, a.T @ torque
    u_p, phi, psi = _marker_point(data, marker, y_b)
    parts = [force, 2.0 * h.T @ (skew(u_p) @ f_body + tau_body)]
    if phi is not None:
        parts.append(phi.T @ f_body + psi.T @ tau_body)
    return jnp.concatenate(parts)
