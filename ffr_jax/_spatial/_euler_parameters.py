"""Euler parameters (unit quaternions) `p = (e0, e1, e2, e3)` of a body's rotation.

The rotation is a function of the direction of `p` only, `A(p) = A(p / |p|)`, so a drift of `|p|` along a
numerical solution does not change the motion; see `_rigid_body` for why the normalisation is handled
this way rather than as a constraint equation. With `p = (e0, e)` of unit length (Nikravesh 1988,
Sect. 6.3):

- `A = (e0^2 - e.e) I + 2 e e^T + 2 e0 e~`,
- `omega' = 2 G(p) pdot`, the angular velocity in body coordinates, `G = [-e, e0 I - e~]` `(3, 4)`;
  this `Z^-1` of paper eq. 6 has `G p = 0`, `G G^T = I`, and `G(pdot) pdot = 0`.
"""

import jax.numpy as jnp
import numpy as np


def skew(v):
    """`v~`, the cross-product matrix: `v~ w = v x w`."""
    z = jnp.zeros((), v.dtype)
    return jnp.array([[z, -v[2], v[1]], [v[2], z, -v[0]], [-v[1], v[0], z]])


def unit(p):
    """`(p / |p|, |p|)`."""
    n = jnp.sqrt(jnp.sum(p * p))
    return p / n, n


def rotation_matrix(p):
    """`A(p / |p|)`, the rotation matrix `(3, 3)` of Euler parameters `p` `(4,)` of any non-zero length.

    Written entry by entry as quadratic forms of `p` over `|p|^2` (the same `A` as the formula above, in a third
    of the operations: every joint and body evaluates it, and its derivatives, many times per step).
    """
    e0, e1, e2, e3 = p[0], p[1], p[2], p[3]
    s00, s11, s22, s33 = e0 * e0, e1 * e1, e2 * e2, e3 * e3
    s01, s02, s03, s12, s13, s23 = e0 * e1, e0 * e2, e0 * e3, e1 * e2, e1 * e3, e2 * e3
    entries = jnp.stack([s00 + s11 - s22 - s33, 2.0 * (s12 - s03), 2.0 * (s13 + s02),
                         2.0 * (s12 + s03), s00 - s11 + s22 - s33, 2.0 * (s23 - s01),
                         2.0 * (s13 - s02), 2.0 * (s23 + s01), s00 - s11 - s22 + s33])
    return (entries / (s00 + s11 + s22 + s33)).reshape(3, 3)


def kinematic_matrix(p):
    """`G(p) = [-e, e0 I - e~]` `(3, 4)` (linear in `p`): `omega' = 2 G pdot` for unit `p`."""
    e0, e = p[0], p[1:]
    return jnp.concatenate([-e[:, None], e0 * jnp.eye(3, dtype=p.dtype) - skew(e)], axis=1)


def angular_velocity(p, pdot):
    """Body-frame angular velocity `omega' = 2 G(p) pdot / |p|^2` of `A(p / |p|)` `(3,)`.

    Exact for any length of `p`: `d(p/|p|)/dt = (pdot - (u.pdot) u) / |p|` with `u = p / |p|`, and `G(u) u = 0`.
    """
    return 2.0 * kinematic_matrix(p) @ pdot / jnp.sum(p * p)


def euler_parameters(axis, angle) -> np.ndarray:
    """Euler parameters `(cos(angle/2), sin(angle/2) n)` of a rotation by `angle` about `axis` (normalised).

    **Arguments:**
    - `axis`: `(3,)` non-zero rotation axis; `angle`: the angle in radians.

    **Returns:** `(4,)` NumPy array of unit length.
    """
    n = np.asarray(axis, dtype=float)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0.0:
        raise ValueError(f"The rotation axis must be a finite, non-zero (3,) vector, got {axis!r}.")
    n = n / np.linalg.norm(n)
    return np.concatenate([[np.cos(0.5 * angle)], np.sin(0.5 * angle) * n])


def quaternion_product(a, b) -> np.ndarray:
    """Euler parameters of the rotation `A(a) A(b)` (the quaternion product `a b`), NumPy."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    a0, av, b0, bv = a[0], a[1:], b[0], b[1:]
    return np.concatenate([[a0 * b0 - av @ bv], a0 * bv + b0 * av + np.cross(av, bv)])


def euler_parameter_rates(p, omega_body):
    """`pdot = 1/2 G(p)^T omega'`: the Euler parameter rates of body-frame angular velocity `omega'`.

    For unit `p` this `pdot` is tangent (`p . pdot = 0`) and `angular_velocity(p, pdot) = omega'`.

    **Arguments:**
    - `p`: `(4,)` unit Euler parameters; `omega_body`: `(3,)` angular velocity in body coordinates.

    **Returns:** `(4,)`.
    """
    p = jnp.asarray(p, dtype=float)
    return 0.5 * kinematic_matrix(p).T @ jnp.asarray(omega_body, dtype=float)
