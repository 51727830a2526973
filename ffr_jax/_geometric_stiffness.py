"""Geometric (stress) stiffness of the Q4 rod under the centrifugal load of a unit rotation rate.

A body spinning at rate `omega` about its frame origin carries, quasi-statically, the body load
`rho omega^2 c` (per unit volume, `c` the undeformed position in the body frame). Its consistent
nodal load is `omega^2 M c` (exact: `c` is linear, so the bilinear shape functions interpolate it
exactly). The static displacement `u_1` of the unit load solves

`K_ff u_1 = (M c)_f`

with the hinged supports of the modes (`u_x(A)`, `u_y(A)`, `u_y(B)` held; REFERENCE_CASE §2), and
the element stresses at the 2x2 Gauss points are `sigma_1 = E_e D B u_1` (plane stress, `D` for
`E = 1`). The geometric stiffness of a stress field `sigma` (the second-order strain energy of the
pre-stress) is, per element and for each displacement component separately,

`K_G,e = t sum_g (dN/dxy)_g^T S_g (dN/dxy)_g det(J) w_g`,  `S = [[sigma_xx, tau_xy], [tau_xy, sigma_yy]]`,

and its modal projection `K_geo = Phi^T K_G(sigma_1) Phi` is the stiffening matrix per unit
`omega^2`. Every step is a differentiable function of the element properties and the modes,
so `K_geo(x)` carries design gradients.

References: Cook, Malkus, Plesha and Witt, *Concepts and Applications of Finite Element
Analysis* (4th ed., 2002), §18.2 (geometric stiffness of plane elements); Wallrapp and Schwertassek,
*Dynamik flexibler Mehrkörpersysteme* (1999) and Wallrapp, Mech. Struct. Mach. 22 (1994)
(geometric stiffening from unit load cases in the standard input data).
"""

import functools

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._fe import _GAUSS, RodMesh, _shape_functions
from ._typing import ElementField


@functools.cache
def _gauss_gradients(dx: float, dy: float) -> tuple[np.ndarray, float]:
    """Cartesian shape-function gradients `(4 gauss points, 2, 4 nodes)` of a `dx x dy` Q4 and `det(J)`.

    Gauss points in the order of `q4_element_matrices` (`xi` outer, `eta` inner); weights are 1.
    """
    inv_j = np.diag([2.0 / dx, 2.0 / dy])
    grads = np.stack([inv_j @ _shape_functions(xi, eta)[1] for xi in _GAUSS for eta in _GAUSS])
    return grads, dx * dy / 4.0


def _plane_stress_matrix(nu: float) -> np.ndarray:
    return np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]]) / (1.0 - nu**2)


def element_stresses(mesh: RodMesh, youngs: ElementField, u: Float[Array, " n_dof"]) -> Float[Array, "n_elements 4 3"]:
    """Plane stresses `(sigma_xx, sigma_yy, tau_xy)` at the 2x2 Gauss points of every element.

    `sigma = E_e D B_g u_e` with the element displacements `u_e` gathered from `u`.
    """
    grads, _ = _gauss_gradients(mesh.dx, mesh.dy)
    u_e = u[mesh.element_dofs()].reshape(-1, 4, 2)  # (n_e, node, component)
    du = jnp.einsum("gan,enc->egca", jnp.asarray(grads), u_e)  # du_c/dx_a at each Gauss point
    strain = jnp.stack([du[..., 0, 0], du[..., 1, 1], du[..., 0, 1] + du[..., 1, 0]], axis=-1)
    return youngs[:, None, None] * (strain @ jnp.asarray(_plane_stress_matrix(mesh.poisson)).T)


def _stress_tensors(stresses):
    sxx, syy, sxy = stresses[..., 0], stresses[..., 1], stresses[..., 2]
    return jnp.stack([jnp.stack([sxx, sxy], -1), jnp.stack([sxy, syy], -1)], -2)


def geometric_stiffness_matrix(mesh: RodMesh, stresses: Float[Array, "n_elements 4 3"]) -> Float[Array, "n_dof n_dof"]:
    """Assembled geometric stiffness `K_G(sigma)`, `(n_dof, n_dof)`, of Gauss-point stresses `(n_e, 4, 3)`."""
    grads, det_j = _gauss_gradients(mesh.dx, mesh.dy)
    g = jnp.asarray(grads)
    k_nodes = mesh.thickness * det_j * jnp.einsum("gan,egab,gbm->enm", g, _stress_tensors(stresses), g)
    k_e = jnp.zeros((k_nodes.shape[0], 8, 8), k_nodes.dtype)
    k_e = k_e.at[:, 0::2, 0::2].set(k_nodes).at[:, 1::2, 1::2].set(k_nodes)
    dofs = mesh.element_dofs()
    rows = np.repeat(dofs, 8, axis=1).ravel()
    cols = np.tile(dofs, (1, 8)).ravel()
    return jnp.zeros((mesh.n_dof, mesh.n_dof), k_e.dtype).at[rows, cols].add(k_e.ravel())


def modal_geometric_stiffness(mesh: RodMesh, stresses: Float[Array, "n_elements 4 3"],
                              modes: Float[Array, "n_dof n_q"]) -> Float[Array, "n_q n_q"]:
    """`Phi^T K_G(sigma) Phi`, element by element (the global `K_G` is never formed)."""
    grads, det_j = _gauss_gradients(mesh.dx, mesh.dy)
    phi_e = modes[mesh.element_dofs()].reshape(-1, 4, 2, modes.shape[1])  # (n_e, node, component, q)
    grad_phi = jnp.einsum("gan,encq->egacq", jnp.asarray(grads), phi_e)
    return mesh.thickness * det_j * jnp.einsum("egacq,egab,egbcr->qr", grad_phi, _stress_tensors(stresses), grad_phi)


def centrifugal_displacement(k: Float[Array, "n_dof n_dof"], m: Float[Array, "n_dof n_dof"],
                             node_coordinates, fixed_dofs: tuple[int, ...]) -> Float[Array, " n_dof"]:
    """Static displacement under the unit centrifugal load `M c`: `K_ff u_f = (M c)_f`, zero on `fixed_dofs`."""
    c = jnp.asarray(node_coordinates, dtype=m.dtype).ravel()
    free = np.setdiff1d(np.arange(k.shape[0]), np.asarray(fixed_dofs, dtype=int))
    load = m @ c
    u_f = jnp.linalg.solve(k[np.ix_(free, free)], load[free])
    return jnp.zeros(k.shape[0], u_f.dtype).at[free].set(u_f)


def centrifugal_geometric_stiffness(mesh: RodMesh, k, m, youngs: ElementField, modes,
                                    fixed_dofs: tuple[int, ...]) -> Float[Array, "n_q n_q"]:
    """Modal geometric stiffness per unit `omega^2` of a rotation about the frame origin (module docstring).

    **Arguments:**
    - `mesh`: the rod mesh; `k`, `m`: `(n_dof, n_dof)` global stiffness and consistent mass.
    - `youngs`: `(n_elements,)` element Young's moduli (for the stresses).
    - `modes`: `(n_dof, n_q)` the retained shape vectors `Phi`.
    - `fixed_dofs`: the supports of the static solve (those of the modes).

    **Returns:** `K_geo = Phi^T K_G(sigma_1) Phi`, `(n_q, n_q)`, symmetric.
    """
    u = centrifugal_displacement(k, m, mesh.node_coordinates(), fixed_dofs)
    return modal_geometric_stiffness(mesh, element_stresses(mesh, youngs, u), modes)
