"""Standard input data of a flexible spatial body in the floating frame of reference.

A material point (a node) with undeformed body coordinates `c` sits at `r = R + A(p) u`, `u = c + Phi q`, and
its elastic rotation is `theta = Psi q`. For a finite element body whose consistent mass matrix is
`M = m_s ⊗ I_3` (true of every isotropic solid or plane element: the same scalar mass matrix `m_s` for each
direction, so `M` commutes with rotations applied node by node), the kinetic energy is a quadratic form whose
coefficients are the mass-weighted moments of the nodal vectors below (`sum_m` stands for `sum_{n, n'} m_s[n, n']`,
`phi_k` for mode `k`'s nodal vectors):

| field               | definition                   | meaning                                                    |
|---------------------|------------------------------|------------------------------------------------------------|
| `mass`              | `sum_m 1`                    | `m`                                                        |
| `first_moment`      | `sum_m c`                    | `s0` `(3,)`, mass times the centre of mass                   |
| `modal_moment`      | `sum_m phi_k`                | `S1` `(3, n_q)`, first moment of the modes                  |
| `second_moment`     | `sum_m c c^T`                | `C0` `(3, 3)`                                              |
| `second_moment_q`   | `sum_m c phi_k^T`            | `C1` `(n_q, 3, 3)`                                         |
| `second_moment_qq`  | `sum_m phi_j phi_k^T`        | `C2` `(n_q, n_q, 3, 3)`, `C2[k, j] = C2[j, k]^T`            |
| `modal_mass`        | `Phi^T M Phi`                | `M_qq` `(n_q, n_q)` (`= tr C2[j, k]`)                      |
| `modal_stiffness`   | `Phi^T K Phi`                | `K_qq` `(n_q, n_q)`                                        |
| `marker_positions`  | `c_P`                        | `(n_markers, 3)` undeformed joint points                    |
| `marker_modes`      | `Phi(c_P)`                   | `(n_markers, 3, n_q)` translation of the joint points       |
| `marker_rotations`  | `Psi(c_P)`                   | `(n_markers, 3, n_q)` elastic rotation of the joint points  |

The second moment of the deformed body is `C(q) = C0 + sum_k q_k (C1[k] + C1[k]^T) + sum_jk q_j q_k C2[j, k]`,
its inertia tensor about the frame origin `J(q) = tr C(q) I - C(q)`: these are the invariants of Schwertassek and
Wallrapp (1999, Sect. 6.5: `I = I0 + I1 q + I2 q q` is `tr C I - C` term by term; their `Ct`, `Cr`, `Gr` are
`S1`, the vector parts of `C1` and of `C2`) and of Shabana (2005, Sect. 5.5: `I_kl`, `S~_kl` from the same sums),
in one symmetric form. A rigid spatial body is [`SpatialBodyData`][]; this class needs at least one mode.

References:
- R. Schwertassek, O. Wallrapp, *Dynamik flexibler Mehrkörpersysteme*, Vieweg 1999.
- A. A. Shabana, *Dynamics of Multibody Systems*, 3rd ed., Cambridge 2005.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


class SpatialFlexibleBodyData(eqx.Module):
    """Standard input data of one flexible spatial body (see the module docstring for each field)."""

    mass: Float[Array, ""]
    first_moment: Float[Array, "3"]
    modal_moment: Float[Array, "3 n_q"]
    second_moment: Float[Array, "3 3"]
    second_moment_q: Float[Array, "n_q 3 3"]
    second_moment_qq: Float[Array, "n_q n_q 3 3"]
    modal_mass: Float[Array, "n_q n_q"]
    modal_stiffness: Float[Array, "n_q n_q"]
    marker_positions: Float[Array, "n_markers 3"]
    marker_modes: Float[Array, "n_markers 3 n_q"]
    marker_rotations: Float[Array, "n_markers 3 n_q"]

    def __check_init__(self):
        _check(self)

    @property
    def n_modes(self) -> int:
        return self.modal_mass.shape[0]

    @property
    def inertia(self):
        """`J0 = tr C0 I - C0` `(3, 3)`, the inertia tensor of the undeformed body about the frame origin."""
        return jnp.trace(self.second_moment) * jnp.eye(3, dtype=self.second_moment.dtype) - self.second_moment


_FIELDS = ("mass", "first_moment", "modal_moment", "second_moment", "second_moment_q", "second_moment_qq",
           "modal_mass", "modal_stiffness", "marker_positions", "marker_modes", "marker_rotations")


def _check(data: SpatialFlexibleBodyData) -> None:
    """Shapes always; where the values are concrete: finite, positive mass, symmetric positive definite modal
    mass, symmetric positive semi-definite modal stiffness, symmetric second moments."""
    shape = lambda a: tuple(np.shape(a))
    n_q = shape(data.modal_mass)[0] if len(shape(data.modal_mass)) == 2 else -1
    n_m = shape(data.marker_positions)[0] if len(shape(data.marker_positions)) == 2 else -1
    expected = {"mass": (), "first_moment": (3,), "modal_moment": (3, n_q), "second_moment": (3, 3),
                "second_moment_q": (n_q, 3, 3), "second_moment_qq": (n_q, n_q, 3, 3), "modal_mass": (n_q, n_q),
                "modal_stiffness": (n_q, n_q), "marker_positions": (n_m, 3), "marker_modes": (n_m, 3, n_q),
                "marker_rotations": (n_m, 3, n_q)}
    for name, want in expected.items():
        got = shape(getattr(data, name))
        if got != want or -1 in want:
            raise ValueError(f"SpatialFlexibleBodyData.{name} has shape {got}, expected {want} (n_q = {n_q} modes "
                             f"from modal_mass, {n_m} markers from marker_positions); see "
                             "ffr_jax.spatial_flexible_body_data.")
    if n_q == 0:
        raise ValueError("SpatialFlexibleBodyData needs at least one mode; a rigid spatial body is "
                         "ffr_jax.spatial_rigid_body_data.")
    leaves = [getattr(data, name) for name in _FIELDS]
    if any(isinstance(a, jax.core.Tracer) for a in leaves):
        return
    values = {name: np.asarray(getattr(data, name), dtype=float) for name in _FIELDS}
    bad = [name for name, v in values.items() if not np.all(np.isfinite(v))]
    if bad:
        raise ValueError(f"SpatialFlexibleBodyData fields {bad} contain NaN or inf.")
    mass = float(values["mass"])
    if not mass > 0.0:
        raise ValueError(f"SpatialFlexibleBodyData.mass must be positive, got {mass}.")
    tol = 1e-8  # the FE quadratic forms are symmetric up to round-off of sums over the mesh
    c0, c2 = values["second_moment"], values["second_moment_qq"]
    if np.max(np.abs(c0 - c0.T)) > tol * max(np.max(np.abs(c0)), 1e-300):
        raise ValueError("SpatialFlexibleBodyData.second_moment (sum m c c^T) must be symmetric.")
    if np.max(np.abs(c2 - np.transpose(c2, (1, 0, 3, 2)))) > tol * max(np.max(np.abs(c2)), 1e-300):
        raise ValueError("SpatialFlexibleBodyData.second_moment_qq must satisfy C2[k, j] = C2[j, k]^T.")
    m_qq, k_qq = values["modal_mass"], values["modal_stiffness"]
    if np.max(np.abs(m_qq - m_qq.T)) > tol * np.max(np.abs(m_qq)) or np.min(np.linalg.eigvalsh(0.5 * (m_qq + m_qq.T))) <= 0:
        raise ValueError("SpatialFlexibleBodyData.modal_mass must be symmetric positive definite (the modes must be "
                         "linearly independent and carry mass).")
    k_sym = 0.5 * (k_qq + k_qq.T)
    k_scale = max(np.max(np.abs(k_sym)), 1e-300)
    if np.max(np.abs(k_qq - k_qq.T)) > tol * k_scale or np.min(np.linalg.eigvalsh(k_sym)) < -tol * k_scale:
        raise ValueError("SpatialFlexibleBodyData.modal_stiffness must be symmetric positive semi-definite.")


def spatial_flexible_body_data(node_masses, node_positions, modes, modal_stiffness, markers,
                               marker_rotations=None) -> SpatialFlexibleBodyData:
    """Body data of a flexible spatial body from lumped node masses (a point-mass model of the body).

    With `M = diag(m_n) ⊗ I_3` every sum of the module docstring is a sum over nodes, e.g. `C0 = sum_n m_n c_n c_n^T`.

    **Arguments:**
    - `node_masses`: `(n_nodes,)` positive masses; `node_positions`: `(n_nodes, 3)` undeformed positions `c_n`.
    - `modes`: `(n_nodes, 3, n_q)` nodal translations `Phi` of each mode.
    - `modal_stiffness`: `(n_q, n_q)` `K_qq`.
    - `markers`: tuple of node indices, the joint points.
    - `marker_rotations`: `(n_markers, 3, n_q)` elastic rotations `Psi` at the markers (default zero: point
      masses carry no rotation; give them where a joint fixes an axis of a flexible body).

    **Returns:** a [`SpatialFlexibleBodyData`][].
    """
    m = jnp.asarray(node_masses, dtype=float)
    c = jnp.asarray(node_positions, dtype=float)
    phi = jnp.asarray(modes, dtype=float)
    idx = np.asarray(markers, dtype=int).reshape(-1)
    rot = jnp.zeros((idx.size, 3, phi.shape[2])) if marker_rotations is None else jnp.asarray(marker_rotations, float)
    return SpatialFlexibleBodyData(
        mass=jnp.sum(m),
        first_moment=m @ c,
        modal_moment=jnp.einsum("n,nak->ak", m, phi),
        second_moment=jnp.einsum("n,na,nb->ab", m, c, c),
        second_moment_q=jnp.einsum("n,na,nbk->kab", m, c, phi),
        second_moment_qq=jnp.einsum("n,naj,nbk->jkab", m, phi, phi),
        modal_mass=jnp.einsum("n,naj,nak->jk", m, phi, phi),
        modal_stiffness=jnp.asarray(modal_stiffness, dtype=float),
        marker_positions=c[idx],
        marker_modes=phi[idx],
        marker_rotations=rot,
    )
