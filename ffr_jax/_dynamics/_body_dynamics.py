"""Equations of motion of one free planar body from its standard input data (paper eq. 8).

Body coordinates `y_b = (R_x, R_y, theta, q)` and velocities `z_b = dy_b/dt` (in the plane the
kinematic matrix `Z` of paper eq. 6 is the identity). With `u = c + Phi q` a node's position in
the body frame, `A` the rotation by `theta` and `I~` the rotation by +90 degrees,

`rdot = Rdot + A (theta' I~ u + Phi q')`,
`rddot = Rddot + A (theta'' I~ u + Phi q'' - theta'^2 u + 2 theta' I~ Phi q')`,

and the virtual work `sum_n delta r_n^T M rddot_n` gives `M_b(y_b) zdot_b + h_omega = h_a` with
(`S_u = s0 + S1 q`):

- `M_RR = m I`, `M_Rtheta = A I~ S_u`, `M_Rq = A S1`,
- `M_thetatheta = J0 + 2 j1.q + q^T M_qq q`, `M_thetaq = (G0 + G q)^T`, `M_qq`,
- `h_omega,R = A (-theta'^2 S_u + 2 theta' I~ S1 q')`,
- `h_omega,theta = 2 theta' (j1 + M_qq q).q'`,
- `h_omega,q = -theta'^2 (j1 + M_qq q) + 2 theta' G q'`, and the inner force `h_e = K_qq q`.

A body is planar or spatial by its data: the functions below take [`BodyData`][] (planar, above) or
[`SpatialBodyData`][] (a rigid spatial body in Euler parameters, `ffr_jax._spatial._rigid_body`) or
[`SpatialFlexibleBodyData`][] (a flexible spatial body, `ffr_jax._spatial._flexible_body`) and dispatch on that type at trace time, so a planar scene traces exactly the planar code.
"""

import jax.numpy as jnp

from .._scene._body_data import BodyData
from .._spatial import _rigid_body as spatial
from .._spatial._body_data import SpatialBodyData
from .._spatial import _flexible_body as spatial_flexible
from .._spatial._flexible_body_data import SpatialFlexibleBodyData


def rotation(theta):
    """The planar rotation matrix `A(theta)`."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, -s], [s, c]])


def rotate(theta, v):
    """`A(theta) v` for a 2-vector or each column of a `(2, k)` array, written out elementwise.

    The products of the equations of motion are tiny (2 x 2, 2 x n_q); written as elementwise
    arithmetic they fuse with their neighbours, where a matrix product would be a kernel of its own.
    """
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _matvec(m, v):
    """`m @ v` for a tiny matrix, as an elementwise product and a sum (see [`rotate`][])."""
    return jnp.sum(m * v, axis=-1)


def _perp(v):
    """`I~ v`: rotation of a 2-vector (or each column of a `(2, k)` array) by +90 degrees."""
    return jnp.stack([-v[1], v[0]])


def split_body_coordinates(y_b, n_modes: int):
    """`y_b -> (R, theta, q)`."""
    del n_modes
    return y_b[:2], y_b[2], y_b[3:]


def body_coordinate_names(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData) -> tuple[str, ...]:
    """Names of a body's coordinates: `R_x, R_y, theta, q_1, ...` (planar) or `R_x, R_y, R_z, e0..e3` (spatial)."""
    if isinstance(data, SpatialBodyData):
        return ("R_x", "R_y", "R_z", "e0", "e1", "e2", "e3")
    if isinstance(data, SpatialFlexibleBodyData):
        return ("R_x", "R_y", "R_z", "e0", "e1", "e2", "e3") + tuple(f"q_{k + 1}" for k in range(data.n_modes))
    return ("R_x", "R_y", "theta") + tuple(f"q_{k + 1}" for k in range(data.n_modes))


def body_strain_energy(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData, y_b):
    """`1/2 q^T K_qq q` of a flexible body (zero for a rigid spatial body)."""
    if isinstance(data, SpatialBodyData):
        return jnp.zeros((), y_b.dtype)
    if isinstance(data, SpatialFlexibleBodyData):
        return spatial_flexible.strain_energy(data, y_b)
    q = y_b[3:]
    return 0.5 * q @ data.modal_stiffness @ q


def body_mass_matrix(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData, y_b):
    """Mass matrix `M_b(y_b)`, `(3 + n_q, 3 + n_q)` (planar) or `(7, 7)` (spatial), symmetric positive definite."""
    if isinstance(data, SpatialBodyData):
        return spatial.mass_matrix(data, y_b)
    if isinstance(data, SpatialFlexibleBodyData):
        return spatial_flexible.mass_matrix(data, y_b)
    _, theta, q = split_body_coordinates(y_b, data.n_modes)
    s_u = data.first_moment + _matvec(data.modal_moment, q)
    mq = data.inertia_q + _matvec(data.modal_mass, q)
    m_rr = data.mass * jnp.eye(2, dtype=s_u.dtype)
    m_rt = rotate(theta, _perp(s_u))
    m_rq = rotate(theta, data.modal_moment)
    m_tt = data.inertia + jnp.sum((data.inertia_q + mq) * q)
    m_tq = data.coupling_0 + _matvec(data.coupling, q)
    top = jnp.concatenate([m_rr, m_rt[:, None], m_rq], axis=1)
    mid = jnp.concatenate([m_rt[None, :], m_tt[None, None], m_tq[None, :]], axis=1)
    bot = jnp.concatenate([m_rq.T, m_tq[:, None], data.modal_mass], axis=1)
    return jnp.concatenate([top, mid, bot], axis=0)


def body_inertia_and_elastic_forces(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData, y_b, z_b):
    """`-h_omega - h_e`: the quadratic-velocity (Coriolis, centrifugal, gyroscopic) and elastic forces."""
    if isinstance(data, SpatialBodyData):
        return spatial.inertia_forces(data, y_b, z_b)
    if isinstance(data, SpatialFlexibleBodyData):
        return spatial_flexible.inertia_and_elastic_forces(data, y_b, z_b)
    _, theta, q = split_body_coordinates(y_b, data.n_modes)
    _, dtheta, dq = split_body_coordinates(z_b, data.n_modes)
    s_u = data.first_moment + _matvec(data.modal_moment, q)
    mq = data.inertia_q + _matvec(data.modal_mass, q)
    h_r = rotate(theta, -(dtheta**2) * s_u + 2 * dtheta * _perp(_matvec(data.modal_moment, dq)))
    h_t = 2 * dtheta * jnp.sum(mq * dq)
    h_q = -(dtheta**2) * mq + 2 * dtheta * _matvec(data.coupling, dq) + _matvec(data.modal_stiffness, q)
    return -jnp.concatenate([h_r, h_t[None], h_q])


def marker_position(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData, marker: int, y_b):
    """Inertial position `r_P = R + A(theta) (c_P + Phi_P q)` of body marker `marker` (`R + A(p) u_P` spatial)."""
    if isinstance(data, SpatialBodyData):
        return spatial.marker_position(data, marker, y_b)
    if isinstance(data, SpatialFlexibleBodyData):
        return spatial_flexible.marker_position(data, marker, y_b)
    r, theta, q = split_body_coordinates(y_b, data.n_modes)
    return r + rotate(theta, data.marker_positions[marker] + _matvec(data.marker_modes[marker], q))


def body_kinetic_energy(data: BodyData | SpatialBodyData | SpatialFlexibleBodyData, y_b, z_b):
    """`T = 1/2 z_b^T M_b(y_b) z_b` from the body data (spatial: without the radial rate of `p`, which carries none)."""
    if isinstance(data, SpatialBodyData):
        return spatial.kinetic_energy(data, y_b, z_b)
    if isinstance(data, SpatialFlexibleBodyData):
        return spatial_flexible.kinetic_energy(data, y_b, z_b)
    return 0.5 * z_b @ body_mass_matrix(data, y_b) @ z_b
