"""Standard input data (SID) of a planar body in the floating frame of reference.

A material point with undeformed body coordinates `c` sits at `r = R + A(theta) (c + Phi(c) q)`.
For a finite element body the kinetic energy `T = 1/2 rdot_n^T M rdot_n` over all nodes is a
quadratic form whose coefficients are the body integrals below, all quadratic forms of the
consistent mass matrix `M` with nodal vectors (exact for the FE discretisation). With `I~` the
rotation by +90 degrees applied node by node, `e_x`, `e_y` the nodal translation vectors and `c`
the stacked undeformed coordinates:

| field         | definition            | meaning                                   |
|---------------|-----------------------|-------------------------------------------|
| `mass`        | `e_x^T M e_x`         | total mass `m`                            |
| `first_moment`| `[e_x, e_y]^T M c`    | `s0`, mass times centre of mass           |
| `modal_moment`| `[e_x, e_y]^T M Phi`  | `S1` `(2, n_q)`, first moment of the modes|
| `inertia`     | `c^T M c`             | `J0`, polar inertia about the frame origin|
| `inertia_q`   | `Phi^T M c`           | `j1` `(n_q,)`                             |
| `modal_mass`  | `Phi^T M Phi`         | `M_qq` `(n_q, n_q)` (identity if normalised)|
| `coupling_0`  | `Phi^T M I~ c`        | `G0` `(n_q,)`, rotation–deformation coupling|
| `coupling`    | `Phi^T M I~ Phi`      | `G` `(n_q, n_q)`, skew-symmetric (gyroscopic)|
| `modal_stiffness` | `Phi^T K Phi`     | `K_qq` `(n_q, n_q)`                       |
| `marker_positions` | `c_P`            | `(n_markers, 2)` undeformed joint points  |
| `marker_modes`| `Phi(c_P)`            | `(n_markers, 2, n_q)` shape-function rows |

(`M` of a plane element is `m_s ⊗ I_2` in interleaved degrees of freedom, so it commutes with
rotations applied node by node; this is what makes the kinetic energy a function of these few
integrals.) A rigid body is the same data with `n_q = 0`. The design side computes these data
for a finite element body (`ffr_jax._design.body_data`).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float



class BodyData(eqx.Module):
    """Standard input data of one planar body (see the module docstring for each field)."""

    mass: Float[Array, ""]
    first_moment: Float[Array, "2"]
    modal_moment: Float[Array, "2 n_q"]
    inertia: Float[Array, ""]
    inertia_q: Float[Array, " n_q"]
    modal_mass: Float[Array, "n_q n_q"]
    coupling_0: Float[Array, " n_q"]
    coupling: Float[Array, "n_q n_q"]
    modal_stiffness: Float[Array, "n_q n_q"]
    marker_positions: Float[Array, "n_markers 2"]
    marker_modes: Float[Array, "n_markers 2 n_q"]

    def __check_init__(self):
        _check_body_data(self)

    @property
    def n_modes(self) -> int:
        return self.modal_mass.shape[0]


def _check_body_data(data: BodyData) -> None:
    """Shapes always; values (finite, positive mass and inertia, symmetric positive definite modal mass,
    symmetric positive semi-definite modal stiffness, skew-symmetric coupling) where they are concrete.

    Body data built inside a traced function (a design map under `jax.jit`) are checked for shape
    only; the design side guarantees the rest there.
    """
    shape = lambda a: tuple(np.shape(a))
    n_q = shape(data.modal_mass)[0] if len(shape(data.modal_mass)) == 2 else -1
    n_m = shape(data.marker_positions)[0] if len(shape(data.marker_positions)) == 2 else -1
    expected = {
        "mass": (), "first_moment": (2,), "modal_moment": (2, n_q), "inertia": (), "inertia_q": (n_q,),
        "modal_mass": (n_q, n_q), "coupling_0": (n_q,), "coupling": (n_q, n_q), "modal_stiffness": (n_q, n_q),
        "marker_positions": (n_m, 2), "marker_modes": (n_m, 2, n_q),
    }
    for name, want in expected.items():
        got = shape(getattr(data, name))
        if got != want or -1 in want:
            raise ValueError(
                f"BodyData.{name} has shape {got}, expected {want} (n_q = {n_q} modes from modal_mass, "
                f"{n_m} markers from marker_positions); see ffr_jax.rigid_body_data, or ffr_jax.DesignedBody.body_data for a finite element body."
            )
    leaves = [getattr(data, name) for name in expected]
    if any(isinstance(a, jax.core.Tracer) for a in leaves):
        return
    values = {name: np.asarray(getattr(data, name), dtype=float) for name in expected}
    bad = [name for name, v in values.items() if not np.all(np.isfinite(v))]
    if bad:
        raise ValueError(f"BodyData fields {bad} contain NaN or inf.")
    mass, inertia, s0 = float(values["mass"]), float(values["inertia"]), values["first_moment"]
    if not mass > 0.0:
        raise ValueError(f"BodyData.mass must be positive, got {mass}.")
    # Polar inertia about the frame origin: J0 >= |s0|^2 / m (parallel axes), equality for a point mass.
    if not inertia >= (s0 @ s0) / mass * (1.0 - 1e-12):
        raise ValueError(
            f"BodyData.inertia {inertia} is below |first_moment|^2 / mass = {(s0 @ s0) / mass}: the polar "
            "moment of inertia about the frame origin cannot be smaller than that of the mass at the centre "
            "of mass (parallel-axis theorem). Check the inertia's reference point."
        )
    if n_q == 0:
        return
    m_qq, k_qq, g = values["modal_mass"], values["modal_stiffness"], values["coupling"]
    tol = 1e-8  # the FE quadratic forms are symmetric up to round-off of sums over the mesh
    if np.max(np.abs(m_qq - m_qq.T)) > tol * np.max(np.abs(m_qq)):
        raise ValueError("BodyData.modal_mass must be symmetric.")
    if np.min(np.linalg.eigvalsh(0.5 * (m_qq + m_qq.T))) <= 0.0:
        raise ValueError("BodyData.modal_mass must be positive definite (the modes must be linearly independent "
                         "and carry mass).")
    if np.max(np.abs(k_qq - k_qq.T)) > tol * max(np.max(np.abs(k_qq)), 1e-300):
        raise ValueError("BodyData.modal_stiffness must be symmetric.")
    k_sym = 0.5 * (k_qq + k_qq.T)
    if np.min(np.linalg.eigvalsh(k_sym)) < -tol * max(np.max(np.abs(k_sym)), 1e-300):
        raise ValueError("BodyData.modal_stiffness must be positive semi-definite (a negative eigenvalue makes the "
                         "body unstable).")
    if np.max(np.abs(g + g.T)) > tol * max(np.max(np.abs(g)), np.max(np.abs(m_qq))):
        raise ValueError("BodyData.coupling (Phi^T M I~ Phi) must be skew-symmetric.")


def rigid_body_data(mass, first_moment, inertia, marker_positions) -> BodyData:
    """Body data of a rigid body: mass, first moment `m c_G` and polar inertia about the frame origin.

    **Arguments:**
    - `mass`: scalar mass.
    - `first_moment`: `(2,)` mass times the centre of mass in body coordinates.
    - `inertia`: polar moment of inertia about the body-frame origin.
    - `marker_positions`: `(n_markers, 2)` joint points in body coordinates.
    """
    marker_positions = jnp.asarray(marker_positions, dtype=float).reshape(-1, 2)
    n_markers = marker_positions.shape[0]
    return BodyData(
        mass=jnp.asarray(mass, dtype=float),
        first_moment=jnp.asarray(first_moment, dtype=float),
        modal_moment=jnp.zeros((2, 0)),
        inertia=jnp.asarray(inertia, dtype=float),
        inertia_q=jnp.zeros((0,)),
        modal_mass=jnp.zeros((0, 0)),
        coupling_0=jnp.zeros((0,)),
        coupling=jnp.zeros((0, 0)),
        modal_stiffness=jnp.zeros((0, 0)),
        marker_positions=marker_positions,
        marker_modes=jnp.zeros((n_markers, 2, 0)),
    )
