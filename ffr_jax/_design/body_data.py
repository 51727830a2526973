"""Standard input data of a finite element body on any quad mesh, from `M`, `K`, the basis and markers.

A material point with undeformed body coordinates `c` sits at `r = R + A(theta) (c + Phi(c) q)`.
The kinetic energy `T = 1/2 rdot_n^T M rdot_n` over all nodes is a quadratic form whose
coefficients are quadratic forms of the consistent mass matrix `M` with nodal vectors (exact for
the FE discretisation). With `I~` the rotation by +90 degrees applied node by node, `e_x`, `e_y`
the nodal translation vectors and `c` the stacked node coordinates:

| field         | definition            | meaning                                   |
|---------------|-----------------------|-------------------------------------------|
| `mass`        | `e_x^T M e_x`         | total mass `m`                            |
| `first_moment`| `[e_x, e_y]^T M c`    | `s0`, mass times centre of mass           |
| `modal_moment`| `[e_x, e_y]^T M Phi`  | `S1` `(2, n_q)`                           |
| `inertia`     | `c^T M c`             | `J0`, polar inertia about the frame origin|
| `inertia_q`   | `Phi^T M c`           | `j1` `(n_q,)`                             |
| `modal_mass`  | `Phi^T M Phi`         | `M_qq` `(n_q, n_q)`                       |
| `coupling_0`  | `Phi^T M I~ c`        | `G0` `(n_q,)`                             |
| `coupling`    | `Phi^T M I~ Phi`      | `G` `(n_q, n_q)`, skew-symmetric          |
| `modal_stiffness` | `Phi^T K Phi`     | `K_qq` `(n_q, n_q)`                       |
| `marker_positions` | `c_P`            | `(n_markers, 2)` undeformed joint points  |
| `marker_modes`| `Phi(c_P)`            | `(n_markers, 2, n_q)` shape-function rows |

These are the fields of `BodyData` (`ffr_jax._scene._body_data`); none assumes `Phi^T M Phi = I`, so the basis
may hold static (interface) modes. A marker is a node, or a set of nodes standing for the point
at their centroid: `c_P` is the mean of their positions and `Phi(c_P)` the mean of their
displacement rows — for a rigid interface (pin in a bushing) exactly the translation of the
centroid, otherwise the least-squares rigid-motion fit of the rim at its centroid.
"""

import jax.numpy as jnp
import numpy as np

from .._scene._body_data import BodyData
from .assembly import FEModel
from .mesh import QuadMesh


Marker = int | tuple[int, ...]


def marker_node_sets(mesh: QuadMesh, markers) -> tuple[tuple[int, ...], ...]:
    """Validate markers (a node index, or a tuple of node indices each) and return them as node sets."""
    if not isinstance(markers, tuple):
        raise TypeError(f"markers must be a tuple of node indices or node tuples, got {type(markers).__name__}.")
    sets = []
    for k, marker in enumerate(markers):
        nodes = (marker,) if isinstance(marker, (int, np.integer)) else marker
        sets.append(mesh.check_nodes(nodes, f"marker {k}"))
    return tuple(sets)


def _rotate_nodewise(v):
    """`I~ v` node by node: `(u_x, u_y) -> (-u_y, u_x)` for stacked vectors `(2 n, ...)`."""
    pairs = v.reshape((v.shape[0] // 2, 2) + v.shape[1:])
    return jnp.stack([-pairs[:, 1], pairs[:, 0]], axis=1).reshape(v.shape)


def body_data(model: FEModel, stiffness, mass, modes, markers: tuple) -> BodyData:
    """Standard input data of a finite element body (see the module docstring for each field).

    **Arguments:**
    - `model`: the [`FEModel`][] (node coordinates in the body frame).
    - `stiffness`, `mass`: global `K`, `M` — `(n_dof, n_dof)` arrays or [`ElementOperator`][]s
      (anything with `@`).
    - `modes`: `(n_dof, n_q)` the shape vectors `Phi` (need not be M-orthonormal).
    - `markers`: static tuple; each entry a node index or a tuple of node indices (a point at
      their centroid).

    **Returns:** a `BodyData`.
    """
    sets = marker_node_sets(model.mesh, markers)
    n_nodes = model.mesh.n_nodes
    coords = model.coordinates
    c = coords.ravel()
    e = jnp.zeros((2 * n_nodes, 2), dtype=c.dtype).at[0::2, 0].set(1.0).at[1::2, 1].set(1.0)
    m_phi = mass @ modes
    m_c = mass @ c
    m_e = mass @ e
    nodal = modes.reshape(n_nodes, 2, modes.shape[1])
    positions = jnp.stack([coords[np.asarray(s)].mean(axis=0) for s in sets]) if sets else jnp.zeros((0, 2))
    rows = (jnp.stack([nodal[np.asarray(s)].mean(axis=0) for s in sets]) if sets
            else jnp.zeros((0, 2, modes.shape[1])))
    return BodyData(
        mass=e[:, 0] @ m_e[:, 0],
        first_moment=e.T @ m_c,
        modal_moment=e.T @ m_phi,
        inertia=c @ m_c,
        inertia_q=modes.T @ m_c,
        modal_mass=modes.T @ m_phi,
        coupling_0=m_phi.T @ _rotate_nodewise(c),
        coupling=m_phi.T @ _rotate_nodewise(modes),
        modal_stiffness=modes.T @ (stiffness @ modes),
        marker_positions=positions,
        marker_modes=rows,
    )
