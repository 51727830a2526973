"""Standard input data of a rigid spatial body.

A material point with body coordinates `u` sits at `r = R + A(p) u`. The kinetic energy of the body is
a quadratic form whose coefficients are the body integrals

| field              | definition                      | meaning                                         |
|--------------------|---------------------------------|-------------------------------------------------|
| `mass`             | `int dm`                        | `m`                                             |
| `first_moment`     | `int u dm`                      | `s` `(3,)`, mass times the centre of mass        |
| `inertia`          | `int (u.u I - u u^T) dm`        | `J` `(3, 3)`, inertia tensor about the frame origin |
| `marker_positions` | `u_P`                           | `(n_markers, 3)` joint points                    |

(Schwertassek and Wallrapp 1999: `m`, `mc`, `I` of the spatial standard input data with no modes.)
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


class SpatialBodyData(eqx.Module):
    """Standard input data of one rigid spatial body (see the module docstring for each field)."""

    mass: Float[Array, ""]
    first_moment: Float[Array, "3"]
    inertia: Float[Array, "3 3"]
    marker_positions: Float[Array, "n_markers 3"]

    def __check_init__(self):
        _check(self)

    @property
    def n_modes(self) -> int:
        return 0


def _check(data: SpatialBodyData) -> None:
    """Shapes always; where the values are concrete: finite, positive mass, symmetric inertia whose part about
    the centre of mass is positive definite and satisfies the triangle inequalities of principal moments."""
    expected = {"mass": (), "first_moment": (3,), "inertia": (3, 3)}
    for name, want in expected.items():
        got = tuple(np.shape(getattr(data, name)))
        if got != want:
            raise ValueError(f"SpatialBodyData.{name} has shape {got}, expected {want}; see "
                             "ffr_jax.spatial_rigid_body_data.")
    if np.ndim(data.marker_positions) != 2 or np.shape(data.marker_positions)[1] != 3:
        raise ValueError(f"SpatialBodyData.marker_positions must have shape (n_markers, 3), got "
                         f"{tuple(np.shape(data.marker_positions))}.")
    leaves = [data.mass, data.first_moment, data.inertia, data.marker_positions]
    if any(isinstance(a, jax.core.Tracer) for a in leaves):
        return
    if not all(np.all(np.isfinite(np.asarray(a))) for a in leaves):
        raise ValueError("SpatialBodyData contains NaN or inf.")
    mass, s, j = float(data.mass), np.asarray(data.first_moment), np.asarray(data.inertia)
    if not mass > 0.0:
        raise ValueError(f"SpatialBodyData.mass must be positive, got {mass}.")
    scale = max(np.max(np.abs(j)), 1e-300)
    if np.max(np.abs(j - j.T)) > 1e-12 * scale:
        raise ValueError(f"SpatialBodyData.inertia must be symmetric, got {j.tolist()}.")
    # Parallel axes: J_O = J_G + (|s|^2 I - s s^T) / m.
    j_g = j - ((s @ s) * np.eye(3) - np.outer(s, s)) / mass
    lam = np.linalg.eigvalsh(0.5 * (j_g + j_g.T))
    if lam[0] <= 0.0 or lam[2] > (lam[0] + lam[1]) * (1.0 + 1e-12):
        raise ValueError(
            f"SpatialBodyData.inertia is not the inertia of a body: about the centre of mass its principal moments "
            f"{lam.tolist()} must be positive and each at most the sum of the other two. Check that the inertia is "
            "taken about the body-frame origin (J_O = J_G + (|s|^2 I - s s^T) / m)."
        )


def spatial_rigid_body_data(mass, first_moment, inertia, marker_positions) -> SpatialBodyData:
    """Body data of a rigid spatial body.

    **Arguments:**
    - `mass`: scalar mass `m`.
    - `first_moment`: `(3,)` `s = m c_G`, mass times the centre of mass in body coordinates.
    - `inertia`: `(3, 3)` inertia tensor about the body-frame origin (not about the centre of mass).
    - `marker_positions`: `(n_markers, 3)` joint points in body coordinates.

    **Returns:** a [`SpatialBodyData`][].
    """
    return SpatialBodyData(
        mass=jnp.asarray(mass, dtype=float),
        first_moment=jnp.asarray(first_moment, dtype=float),
        inertia=jnp.asarray(inertia, dtype=float),
        marker_positions=jnp.asarray(marker_positions, dtype=float).reshape(-1, 3),
    )
