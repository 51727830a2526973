"""Spatial body data of a solid finite element body from its node coordinates, `M`, `K` and modes.

The 3-D generalisation of [`lifted_body_data`][]. An isotropic solid element's consistent (or lumped) mass matrix is
`M = m_s ⊗ I_3` with the degrees of freedom interleaved (`u_x, u_y, u_z` of node `n` at `3 n, 3 n + 1, 3 n + 2`),
so `sum_m a b = a^T m_s b` for any two scalar nodal fields `a`, `b`, and every moment of
[`SpatialFlexibleBodyData`][] comes from one product of `M` with the scalar fields `1, c_x, c_y, c_z,
phi_kx, phi_ky, phi_kz` placed in the `x` slots: `G = F^T m_s F`, `F = [1, c, phi_1, ..., phi_nq]` `(n_nodes, 4 + 3 n_q)`.

The elastic rotation `Psi` of a marker is that of the least-squares rigid fit of its rotation patch's nodal
displacements (the patch: the marker's own nodes when they span a plane, else the nodes of every element touching
them): with `d_i` the nodes' offsets from their centroid, `u_i = phi_k(node i)`, minimising
`sum_i |u_i - t - theta x d_i|^2` gives `t` the mean of `u_i` and

`J theta_k = sum_i d_i x u_i`,  `J = sum_i (|d_i|^2 I - d_i d_i^T)`,

`J` the patch's (unit-weight) inertia tensor, regular unless the patch's nodes lie on one line. For a planar patch
in `z = 0` and in-plane modes `J` is block-diagonal and `theta_k = (0, 0, sum_i (d_i x u_i)_z / sum_i |d_i|^2)`:
the rotation of the planar lift.
"""

import numpy as np
import jax.numpy as jnp

from ._flexible_body_data import SpatialFlexibleBodyData

# A patch whose unit inertia tensor J has smallest/largest eigenvalue below this is taken as collinear: its rotation
# about the line is undetermined. Exactly collinear nodes give ~1e-16 (round-off of the offsets); the flattest patch
# of a sane mesh (an element of aspect ratio 1e3) gives ~1e-6.
_COLLINEAR_TOLERANCE = 1e-10


def _marker_sets(markers, n_nodes: int) -> tuple[tuple[int, ...], ...]:
    """Validate markers (each a node index or a tuple of distinct node indices) and return them as node sets."""
    if not isinstance(markers, tuple):
        raise TypeError(f"markers must be a tuple of node indices or node tuples, got {type(markers).__name__}.")
    sets = []
    for k, marker in enumerate(markers):
        nodes = (marker,) if isinstance(marker, (int, np.integer)) else marker
        if not isinstance(nodes, tuple) or not nodes or not all(isinstance(n, (int, np.integer)) for n in nodes):
            raise ValueError(f"marker {k} must be a node index or a non-empty tuple of node indices, got {marker!r}.")
        bad = [int(n) for n in nodes if not 0 <= n < n_nodes]
        if bad:
            raise ValueError(f"marker {k} names nodes {bad} outside [0, {n_nodes}); node indices are 0-based rows of "
                             "coordinates.")
        if len(set(int(n) for n in nodes)) != len(nodes):
            raise ValueError(f"marker {k} repeats a node: {nodes}.")
        sets.append(tuple(int(n) for n in nodes))
    return tuple(sets)


def _unit_inertia(points: np.ndarray) -> np.ndarray:
    d = points - points.mean(axis=0)
    return np.sum(d * d) * np.eye(3) - d.T @ d


def _is_collinear(points: np.ndarray) -> bool:
    eig = np.linalg.eigvalsh(_unit_inertia(points))
    return len(points) < 3 or not eig[0] > _COLLINEAR_TOLERANCE * max(eig[-1], 1e-300)


def _rotation_patches(coords: np.ndarray, sets, elements) -> tuple[np.ndarray, ...]:
    """The node set whose rigid fit gives each marker's elastic rotation (static: from the geometry alone)."""
    patches = []
    for k, nodes in enumerate(sets):
        patch = np.asarray(nodes)
        if _is_collinear(coords[patch]):
            if elements is None:
                raise ValueError(
                    f"marker {k} (nodes {nodes}) has its nodes on one line, so the rotation of its rigid fit about "
                    "that line is undefined: pass elements= (the mesh connectivity, (n_elements, nodes per "
                    "element)) to fit the patch of elements around it, or give the marker as a tuple of nodes that "
                    "span a plane.")
            touching = np.any(np.isin(elements, patch), axis=1)
            patch = np.unique(elements[touching])
            if _is_collinear(coords[patch]):
                raise ValueError(f"marker {k}: the nodes of the elements around nodes {nodes} lie on one line; "
                                 "check the connectivity.")
        patches.append(patch)
    return tuple(patches)


def solid_body_data(coordinates, stiffness, mass, modes, markers: tuple, *,
                    elements=None) -> SpatialFlexibleBodyData:
    """Spatial standard input data of a solid finite element body (see [`SpatialFlexibleBodyData`][]).

    All moments are the exact quadratic forms of the FE mass matrix `M = m_s ⊗ I_3` with the nodal fields
    `1, c, phi_k` (e.g. `C1[k] = sum_m c phi_k^T`, `C2[j, k] = sum_m phi_j phi_k^T`); `M_qq = Phi^T M Phi`,
    `K_qq = Phi^T K Phi`. A marker sits at the centroid of its nodes and moves with their mean modal
    displacement; its elastic rotation `Psi` is the rotation of the least-squares rigid fit of its patch's modal
    displacements, `J theta_k = sum_i d_i x phi_k(i)` (module docstring). Differentiable in `stiffness`, `mass`
    and `modes` (pure JAX); the geometry is static.

    **Arguments:**
    - `coordinates`: `(n_nodes, 3)` undeformed node coordinates in the body frame (NumPy or concrete JAX array).
    - `stiffness`, `mass`: global `K`, `M` `(3 n_nodes, 3 n_nodes)`, dense arrays, JAX `BCOO` or operators
      (anything with `@` on an `(3 n_nodes, k)` array), degrees of freedom interleaved `u_x, u_y, u_z` per node;
      `M` must be `m_s ⊗ I_3` (the same scalar mass matrix for each direction, as every isotropic solid element's
      consistent or lumped mass matrix is).
    - `modes`: `(3 n_nodes, n_q)` shape vectors `Phi` (need not be M-orthonormal).
    - `markers`: static tuple; each entry a node index or a tuple of node indices (a point at their centroid).
    - `elements`: optional `(n_elements, nodes per element)` connectivity; needed only for a marker whose nodes lie
      on one line (one node, or a line of nodes through a thickness): its rotation comes from the patch of the
      elements touching it.

    **Returns:** a [`SpatialFlexibleBodyData`][] with `n_q` modes.

    **Raises** `ValueError` for wrong shapes, markers outside the mesh, and a collinear marker without `elements`.
    """
    try:
        coords_np = np.asarray(coordinates, dtype=np.float64)
    except Exception as error:  # a tracer: the rotation patches and J need the geometry on the host
        raise ValueError("solid_body_data: coordinates must be concrete (a NumPy array): the geometry is static "
                         "configuration, not a traced value.") from error
    if coords_np.ndim != 2 or coords_np.shape[1] != 3:
        raise ValueError(f"coordinates must have shape (n_nodes, 3), got {coords_np.shape}.")
    n_nodes = coords_np.shape[0]
    modes = jnp.asarray(modes)
    if modes.ndim != 2 or modes.shape[0] != 3 * n_nodes or modes.shape[1] < 1:
        raise ValueError(f"modes must have shape (3 n_nodes, n_q) = ({3 * n_nodes}, n_q >= 1) for {n_nodes} nodes, "
                         f"got {modes.shape}.")
    for name, matrix in (("stiffness", stiffness), ("mass", mass)):
        if tuple(getattr(matrix, "shape", ())) != (3 * n_nodes, 3 * n_nodes):
            raise ValueError(f"{name} must have shape ({3 * n_nodes}, {3 * n_nodes}) for {n_nodes} nodes, got "
                             f"{getattr(matrix, 'shape', None)}.")
    if elements is not None:
        elements = np.asarray(elements)
        if elements.ndim != 2 or not np.issubdtype(elements.dtype, np.integer):
            raise ValueError(f"elements must be an integer array (n_elements, nodes per element), got "
                             f"{elements.dtype} {elements.shape}.")
    sets = _marker_sets(markers, n_nodes)
    patches = _rotation_patches(coords_np, sets, elements)

    n_q = modes.shape[1]
    coords = jnp.asarray(coords_np)
    nodal = modes.reshape(n_nodes, 3, n_q)
    fields = jnp.concatenate([jnp.ones((n_nodes, 1), modes.dtype), coords,
                              jnp.transpose(nodal, (0, 2, 1)).reshape(n_nodes, 3 * n_q)], axis=1)
    in_x = jnp.zeros((3 * n_nodes, fields.shape[1]), fields.dtype).at[0::3].set(fields)
    gram = fields.T @ (mass @ in_x)[0::3]  # sum_m a b for every pair of fields
    gram = 0.5 * (gram + gram.T)
    mode_part = gram[4:, 4:].reshape(n_q, 3, n_q, 3)

    positions = jnp.stack([coords[np.asarray(s)].mean(axis=0) for s in sets])
    rows = jnp.stack([nodal[np.asarray(s)].mean(axis=0) for s in sets])
    rotations = []
    for patch in patches:
        d = coords_np[patch] - coords_np[patch].mean(axis=0)
        u = nodal[patch]
        moment = jnp.stack([d[:, 1] @ u[:, 2] - d[:, 2] @ u[:, 1],
                            d[:, 2] @ u[:, 0] - d[:, 0] @ u[:, 2],
                            d[:, 0] @ u[:, 1] - d[:, 1] @ u[:, 0]])  # sum_i d_i x u_i, (3, n_q)
        rotations.append(jnp.asarray(np.linalg.inv(_unit_inertia(coords_np[patch]))) @ moment)
    return SpatialFlexibleBodyData(
        mass=gram[0, 0],
        first_moment=gram[0, 1:4],
        modal_moment=gram[0, 4:].reshape(n_q, 3).T,
        second_moment=gram[1:4, 1:4],
        second_moment_q=jnp.transpose(gram[1:4, 4:].reshape(3, n_q, 3), (1, 0, 2)),
        second_moment_qq=jnp.transpose(mode_part, (0, 2, 1, 3)),
        modal_mass=modes.T @ (mass @ modes),
        modal_stiffness=modes.T @ (stiffness @ modes),
        marker_positions=positions,
        marker_modes=rows,
        marker_rotations=jnp.stack(rotations),
    )
