"""Equations of motion of one free flexible spatial body in the floating frame of reference (paper eq. 8).

Body coordinates `y_b = (R, p, q)` (`3 + 4 + n_q`: frame origin, Euler parameters, modal coordinates) and
velocities `z_b = dy_b/dt`; the Euler parameters are handled as for the rigid body (`_rigid_body`: `A(p / |p|)`,
`omega' = 2 H pdot` with `H = G(p / |p|) / |p|`, radial rate `rho = u . pdot`, and the regularisation
`1/2 k rho^2` that makes the radial direction carry a positive mass and keeps `|p|` constant).

A node at `r = R + A u`, `u = c + Phi q`, moves with `rdot = Rdot + A (omega' x u + Phi qdot)`. In the velocities
`v = (Rdot, omega', qdot)` the virtual work `sum delta r . M rddot` gives `M_v vdot + h_v` with (notation of
`_flexible_body_data`: `s = s0 + S1 q`, `X_k = sum_m u phi_k^T = C1[k] + sum_j q_j C2[j, k]`, `C(q)` the second
moment, `J = tr C I - C`, `ax(X)` the axial vector of `X - X^T`, i.e. `ax(X)_a = eps_abc X_bc`)

- `M_RR = m I`, `M_Rw = -A s~`, `M_Rq = A S1`, `M_ww = J`, `M_wq = [ax(X_k)]_k`, `M_qq`;
- `h_R = A (w~ w~ s + 2 w~ S1 qdot)`,
- `h_w = w~ J w + 2 (tr D w - D w)` with `D = sum_k qdot_k X_k^T` (`2 sum_m u x (w x Phi qdot)`),
- `h_q,k = w^T X_k w - |w|^2 tr X_k + 2 w . sum_j qdot_j ax(C2[j, k])`, and the inner force `K_qq q`.

(`w` is `omega'`.) With `v = B z_b`, `B = diag(I, 2 H, I)` and `Bdot z_b = (0, -2 (rho / n) omega', 0)`, the body's
equations in `z_b` are `B^T (M_v B zdot_b + M_v Bdot z_b + h_v) + (regularisation) = B^T Q_v`. A lifted planar body
(nodes at `z = 0`, in-plane modes, rotation about `z`) reproduces the planar equations of `_body_dynamics`
exactly.
"""

import jax.numpy as jnp

from ._euler_parameters import kinematic_matrix, rotation_matrix, skew, unit
from ._flexible_body_data import SpatialFlexibleBodyData


def _axial(x):
    """`ax(X)_a = eps_abc X_bc` over the last two axes: `ax(sum_m a b^T) = sum_m a x b`."""
    return jnp.stack([x[..., 1, 2] - x[..., 2, 1], x[..., 2, 0] - x[..., 0, 2], x[..., 0, 1] - x[..., 1, 0]], axis=-1)


def _regularisation(data: SpatialFlexibleBodyData):
    """`k = 4 tr(J0) / 3`, on the scale of the rotational block (as for the rigid body)."""
    return 4.0 * jnp.trace(data.inertia) / 3.0


def split(y_b):
    """`y_b -> (R, p, q)`."""
    return y_b[:3], y_b[3:7], y_b[7:]


def _moments(data: SpatialFlexibleBodyData, q):
    """`(s(q), X_k(q) (n_q, 3, 3), J(q), M_wq (3, n_q))` of the deformed body."""
    s = data.first_moment + data.modal_moment @ q
    x = data.second_moment_q + jnp.einsum("j,jkab->kab", q, data.second_moment_qq)
    c = data.second_moment + jnp.einsum("k,kab->ab", q, data.second_moment_q + jnp.swapaxes(data.second_moment_q, 1, 2))
    c = c + jnp.einsum("j,k,jkab->ab", q, q, data.second_moment_qq)
    j = jnp.trace(c) * jnp.eye(3, dtype=c.dtype) - c
    return s, x, j, _axial(x).T


def _frame(y_b):
    """`(A, H, u, n)` of the Euler parameters."""
    p = y_b[3:7]
    u, n = unit(p)
    return rotation_matrix(p), kinematic_matrix(u) / n, u, n


def velocity_mass_matrix(data: SpatialFlexibleBodyData, y_b):
    """`M_v(y_b)` `(6 + n_q, 6 + n_q)` in the velocities `(Rdot, omega', qdot)` (the kinetic energy is `1/2 v^T M_v v`)."""
    a, _, _, _ = _frame(y_b)
    s, _, j, m_wq = _moments(data, y_b[7:])
    m_rr = data.mass * jnp.eye(3, dtype=a.dtype)
    m_rw = -a @ skew(s)
    m_rq = a @ data.modal_moment
    top = jnp.concatenate([m_rr, m_rw, m_rq], axis=1)
    mid = jnp.concatenate([m_rw.T, j, m_wq], axis=1)
    bot = jnp.concatenate([m_rq.T, m_wq.T, data.modal_mass], axis=1)
    return jnp.concatenate([top, mid, bot], axis=0)


def mass_matrix(data: SpatialFlexibleBodyData, y_b):
    """`M_b(y_b) = B^T M_v B + k u u^T` `(7 + n_q, 7 + n_q)`, symmetric positive definite (blocks written out:
    `M_Rp = 2 M_Rw H`, `M_pp = 4 H^T J H + k u u^T`, `M_pq = 2 H^T M_wq`)."""
    a, h, u, _ = _frame(y_b)
    s, _, j, m_wq = _moments(data, y_b[7:])
    m_rr = data.mass * jnp.eye(3, dtype=a.dtype)
    m_rp = -2.0 * (a @ skew(s)) @ h
    m_rq = a @ data.modal_moment
    m_pp = 4.0 * h.T @ j @ h + _regularisation(data) * jnp.outer(u, u)
    m_pq = 2.0 * h.T @ m_wq
    top = jnp.concatenate([m_rr, m_rp, m_rq], axis=1)
    mid = jnp.concatenate([m_rp.T, m_pp, m_pq], axis=1)
    bot = jnp.concatenate([m_rq.T, m_pq.T, data.modal_mass], axis=1)
    return jnp.concatenate([top, mid, bot], axis=0)


def inertia_and_elastic_forces(data: SpatialFlexibleBodyData, y_b, z_b):
    """`-h_omega - h_e` `(7 + n_q,)`: quadratic-velocity (centrifugal, Coriolis, gyroscopic) and elastic forces,
    `B^T (M_v Bdot z_b + h_v)` plus the radial and elastic terms (the products with `B` written out)."""
    a, h, u, n = _frame(y_b)
    q = y_b[7:]
    pdot, dq = z_b[3:7], z_b[7:]
    omega = 2.0 * h @ pdot
    rho = u @ pdot
    s, x, j, m_wq = _moments(data, q)
    w = skew(omega)
    turn = -2.0 * (rho / n) * omega  # Bdot z_b, the omega' part (the only one)
    h_r = a @ (w @ (w @ s) + 2.0 * (w @ (data.modal_moment @ dq)) - skew(s) @ turn)
    d = jnp.einsum("k,kba->ab", dq, x)
    h_w = w @ (j @ omega) + 2.0 * (jnp.trace(d) * omega - d @ omega) + j @ turn
    h_q = (jnp.einsum("a,kab,b->k", omega, x, omega) - (omega @ omega) * jnp.trace(x, axis1=1, axis2=2)
           + 2.0 * jnp.einsum("a,j,jka->k", omega, dq, _axial(data.second_moment_qq)) + m_wq.T @ turn)
    radial = _regularisation(data) * u * ((pdot @ pdot - rho * rho) / n)
    return -jnp.concatenate([h_r, 2.0 * h.T @ h_w + radial, h_q + data.modal_stiffness @ q])


def marker_position(data: SpatialFlexibleBodyData, marker: int, y_b):
    """Inertial position `r_P = R + A(p) (c_P + Phi_P q)` of body marker `marker`."""
    return y_b[:3] + rotation_matrix(y_b[3:7]) @ (data.marker_positions[marker] + data.marker_modes[marker] @ y_b[7:])


def marker_axis(data: SpatialFlexibleBodyData, marker: int, y_b, axis_body):
    """The inertial direction `A(p) (a + (Psi_P q) x a)` of a body-frame direction `a` at marker `marker`
    (linear in the elastic rotation, as the FFR's small deformations are)."""
    theta = data.marker_rotations[marker] @ y_b[7:]
    return rotation_matrix(y_b[3:7]) @ (axis_body + jnp.cross(theta, axis_body))


def kinetic_energy(data: SpatialFlexibleBodyData, y_b, z_b):
    """`T = 1/2 v^T M_v v` with `v = (Rdot, omega', qdot)` (the radial rate of `p` carries none)."""
    _, h, _, _ = _frame(y_b)
    v = jnp.concatenate([z_b[:3], 2.0 * h @ z_b[3:7], z_b[7:]])
    return 0.5 * v @ velocity_mass_matrix(data, y_b) @ v


def strain_energy(data: SpatialFlexibleBodyData, y_b):
    """`1/2 q^T K_qq q`."""
    q = y_b[7:]
    return 0.5 * q @ data.modal_stiffness @ q


def momenta(data: SpatialFlexibleBodyData, y_b, z_b):
    """Linear momentum `L = m Rdot + A (omega' x s + S1 qdot)` and angular momentum about the inertial origin
    `H_O = R x L + (A s) x Rdot + A (J omega' + M_wq qdot)` (`sum_m r x rdot`), each `(3,)`."""
    a, h, _, _ = _frame(y_b)
    r, rdot, q, dq = y_b[:3], z_b[:3], y_b[7:], z_b[7:]
    omega = 2.0 * h @ z_b[3:7]
    s, _, j, m_wq = _moments(data, q)
    lin = data.mass * rdot + a @ (jnp.cross(omega, s) + data.modal_moment @ dq)
    ang = jnp.cross(r, lin) + jnp.cross(a @ s, rdot) + a @ (j @ omega + m_wq @ dq)
    return lin, ang


def gravity_potential(data: SpatialFlexibleBodyData, acceleration, y_b):
    """`V = -g . (m R + A s(q))` with `s(q) = s0 + S1 q`."""
    s = data.first_moment + data.modal_moment @ y_b[7:]
    return -acceleration @ (data.mass * y_b[:3] + rotation_matrix(y_b[3:7]) @ s)


def gravity_force(data: SpatialFlexibleBodyData, acceleration, y_b):
    """`Q = -dV/dy_b` of [`gravity_potential`][] `(7 + n_q,)`: `Q_R = m g`, `Q_p = 2 H^T s~ A^T g`,
    `Q_q = S1^T A^T g` (written out, as for the rigid body, so the sensitivities see no nested derivative)."""
    a, h, _, _ = _frame(y_b)
    s = data.first_moment + data.modal_moment @ y_b[7:]
    g_body = a.T @ acceleration
    return jnp.concatenate([data.mass * acceleration, 2.0 * h.T @ (skew(s) @ g_body), data.modal_moment.T @ g_body])
