"""A planar finite element body lifted into space: its nodes at `z = 0`, its modes in the plane.

The spatial standard input data ([`SpatialFlexibleBodyData`][]) need the in-plane second moments `sum_m c_a c_b`
one by one (the inertia tensor about in-plane axes), which the planar data (`J0 = c^T M c`, the trace only) do not
hold; they are computed here from the FE mass matrix and the mode shapes, which the design chain has. A plane
element's consistent mass matrix is `m_s ⊗ I_2` (interleaved), so `sum_m a b = a^T m_s b` for any two scalar nodal
fields `a`, `b`: all moments come from one product of `M` with the scalar fields `1, c_x, c_y, phi_kx, phi_ky`
placed in the `x` slots. The body's out-of-plane mass is the same `m_s` (`M = m_s ⊗ I_3` for the lifted body).

Elastic rotations at the markers are about `z` only (in-plane modes): for a marker of several nodes the rotation of
the least-squares rigid fit of their displacements, for a one-node marker that of the patch of elements around the
node, `theta_k = sum_i (d_i x phi_k,i)_z / sum_i |d_i|^2` with `d_i` the nodes' offsets from their centroid.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._design.body_data import marker_node_sets
from ._flexible_body_data import SpatialFlexibleBodyData


def _pad(x, axes):
    """Zero-pad the given axes of `x` from 2 to 3 entries (the `z` component of a lifted vector)."""
    widths = [(0, 1) if k in axes else (0, 0) for k in range(x.ndim)]
    return jnp.pad(x, widths)


def _rotation_patches(mesh, sets) -> tuple[np.ndarray, ...]:
    """The node set whose rigid fit gives each marker's elastic rotation."""
    patches = []
    for nodes in sets:
        if len(nodes) >= 2:
            patches.append(np.asarray(nodes))
        else:
            touching = np.any(mesh.elements == nodes[0], axis=1)
            patches.append(np.unique(mesh.elements[touching]))
    return tuple(patches)


def lifted_body_data(model, stiffness, mass, modes, markers: tuple) -> SpatialFlexibleBodyData:
    """Spatial body data of a planar finite element body lifted to the plane `z = 0`.

    **Arguments:**
    - `model`: the planar `FEModel` (node coordinates in the body frame become `(x, y, 0)`).
    - `stiffness`, `mass`: global `K`, `M` `(n_dof, n_dof)` arrays or `ElementOperator`s (anything with `@`).
    - `modes`: `(n_dof, n_q)` in-plane shape vectors `Phi` (interleaved `u_x, u_y`).
    - `markers`: static tuple; each a node index or a tuple of node indices (a point at their centroid).

    **Returns:** a [`SpatialFlexibleBodyData`][] with `n_q` modes.
    """
    sets = marker_node_sets(model.mesh, markers)
    n_nodes, n_q = model.mesh.n_nodes, modes.shape[1]
    coords = model.coordinates
    nodal = modes.reshape(n_nodes, 2, n_q)
    fields = jnp.concatenate([jnp.ones((n_nodes, 1), coords.dtype), coords,
                              jnp.transpose(nodal, (0, 2, 1)).reshape(n_nodes, 2 * n_q)], axis=1)
    in_x = jnp.zeros((2 * n_nodes, fields.shape[1]), fields.dtype).at[0::2].set(fields)
    gram = fields.T @ (mass @ in_x)[0::2]  # sum_m a b for every pair of fields
    gram = 0.5 * (gram + gram.T)
    mode_part = gram[3:, 3:].reshape(n_q, 2, n_q, 2)
    m_phi = mass @ modes
    positions = jnp.stack([coords[np.asarray(s)].mean(axis=0) for s in sets])
    rows = jnp.stack([nodal[np.asarray(s)].mean(axis=0) for s in sets])
    rotations = []
    for patch in _rotation_patches(model.mesh, sets):
        d = coords[patch] - coords[patch].mean(axis=0)
        u = nodal[patch]
        theta = (d[:, 0] @ u[:, 1, :] - d[:, 1] @ u[:, 0, :]) / jnp.sum(d * d)
        rotations.append(jnp.concatenate([jnp.zeros((2, n_q), theta.dtype), theta[None]], axis=0))
    return SpatialFlexibleBodyData(
        mass=gram[0, 0],
        first_moment=_pad(gram[0, 1:3], (0,)),
        modal_moment=_pad(gram[0, 3:].reshape(n_q, 2).T, (0,)),
        second_moment=_pad(gram[1:3, 1:3], (0, 1)),
        second_moment_q=_pad(jnp.transpose(gram[1:3, 3:].reshape(2, n_q, 2), (1, 0, 2)), (1, 2)),
        second_moment_qq=_pad(jnp.transpose(mode_part, (0, 2, 1, 3)), (2, 3)),
        modal_mass=modes.T @ m_phi,
        modal_stiffness=modes.T @ (stiffness @ modes),
        marker_positions=_pad(positions, (1,)),
        marker_modes=_pad(rows, (1,)),
        marker_rotations=jnp.stack(rotations),
    )


def designed_body_data(body, x) -> SpatialFlexibleBodyData:
    """The lifted spatial body data of a planar `DesignedBody` `body` for its design `x` (the same chain
    `x -> (E_e, rho_e) -> (K, M) -> Phi` as its planar body data)."""
    youngs, densities = body.element_values(x)
    basis = body.reduction(body.model, youngs, densities)
    k, m = body.model.stiffness(youngs), body.model.mass(densities)
    return lifted_body_data(body.model, k, m, basis.modes, body.markers)


@eqx.filter_jit
def _compiled(body, x):
    return designed_body_data(body, x)


def uniform_lifted_body_data(body, value: float = 0.5) -> SpatialFlexibleBodyData:
    """Lifted body data of the uniform design `x_e = value` of a planar `DesignedBody` (a scene template's data),
    value-checked after the compiled computation."""
    data = _compiled(body, body.initial_design(value))
    return SpatialFlexibleBodyData(**{name: getattr(data, name) for name in data.__dataclass_fields__})
