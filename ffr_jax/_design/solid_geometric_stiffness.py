"""Geometric (stress) stiffness of a hexahedral solid body under the centrifugal load of its rotation: six unit cases.

A body turning with angular velocity `omega` (body frame) about its frame origin carries, quasi-statically, the body
load per unit volume

`f = rho (|omega|^2 c - omega (omega . c)) = rho sum_k pi_k f_k(c)`,

linear in the six products `pi = (omega_x^2, omega_y^2, omega_z^2, omega_y omega_z, omega_x omega_z, omega_x omega_y)`
with the unit load fields `f_1 = (0, c_y, c_z)`, `f_2 = (c_x, 0, c_z)`, `f_3 = (c_x, c_y, 0)`, `f_4 = -(0, c_z, c_y)`,
`f_5 = -(c_z, 0, c_x)`, `f_6 = -(c_y, c_x, 0)` (Wallrapp 1994: geometric stiffening from unit load cases). Their
consistent nodal loads are `M f_k(c)` (exact: `c` is trilinear, so the shape functions interpolate it). The static
displacements `u_k` of the six cases solve `K_ff u_k = (M f_k)_f` with the supports `fixed_dofs` held (the
reference conditions of the modes, e.g. the clamped root of a blade), the stresses at the 2x2x2 Gauss points are
`sigma_k = E_e D B u_k` (isotropic `D` for `E = 1`, the trilinear strains), and the geometric stiffness of a
stress field, per element and for each displacement component separately,

`K_G,e = sum_g (dN/dx)_g^T S_g (dN/dx)_g det(J_g) w_g`,  `S` the 3x3 stress tensor,

is projected on the modes element by element: `K_k = Phi^T K_G(sigma_k) Phi`, `(6, n_q, n_q)`. The modal geometric
stiffness of a rotation `omega` is then `K_geo(omega) = sum_k pi_k(omega) K_k`. Every step is a differentiable
function of the element values and the modes, so the six matrices carry design gradients.

For [`H11`][] the stresses are those of the trilinear (compatible) part of the static solution (the incompatible
modes are condensed out of `K` and not recovered); the axial stress of a centrifugally loaded beam, which is what
stiffens its bending, is represented by the trilinear field as for [`H8`][]. Hexahedral meshes only; the static
solve is dense (up to `MAX_DENSE_SOLVE_DOF` degrees of freedom).

!!! cite "References"
    O. Wallrapp, "Standardization of flexible body modeling in multibody system codes, Part I: Definition of
    standard input data", Mech. Struct. Mach. 22 (1994) 283–304.

    R. D. Cook, D. S. Malkus, M. E. Plesha, R. J. Witt, *Concepts and Applications of Finite Element Analysis*,
    4th ed., Wiley (2002), §18.2 (geometric stiffness).
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .element.h8 import gauss_points_2x2x2, trilinear
from .element.solid_base import isotropic
from .geometric_stiffness import MAX_DENSE_SOLVE_DOF
from .solid_assembly import SolidFEModel, solid_dense_matrix
from .solid_modes import rigid_motions

# The six products of the angular velocity's body components, in the order of the load cases.
PRODUCTS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


def angular_velocity_products(omega) -> Float[Array, "6"]:
    """`pi(omega) = (omega_x^2, omega_y^2, omega_z^2, omega_y omega_z, omega_x omega_z, omega_x omega_y)`."""
    return jnp.stack([omega[i] * omega[j] for i, j in PRODUCTS])


def unit_load_fields(coordinates) -> Float[Array, "6 n_nodes 3"]:
    """The unit centrifugal load fields `f_k(c)` of the module docstring at the nodes, `(6, n_nodes, 3)`."""
    x, y, z = coordinates[:, 0], coordinates[:, 1], coordinates[:, 2]
    zero = jnp.zeros_like(x)
    fields = [(zero, y, z), (x, zero, z), (x, y, zero), (zero, -z, -y), (-z, zero, -x), (-y, -x, zero)]
    return jnp.stack([jnp.stack(f, axis=-1) for f in fields])


def _check_hexahedral(model: SolidFEModel) -> None:
    if model.mesh.cell_type != "hexahedron" or model.element_dofs.shape[1] != 24:
        raise ValueError(f"Geometric stiffening of a solid body needs a hexahedral mesh of H8 or H11 elements; this "
                         f"model has {type(model.element).__name__} elements ({model.mesh.cell_type}).")
    if model.n_dof > MAX_DENSE_SOLVE_DOF:
        raise ValueError(
            f"Geometric stiffening solves the centrifugal pre-stress with a dense K: the mesh has {model.n_dof} degrees "
            f"of freedom, above the limit of {MAX_DENSE_SOLVE_DOF}. Use a coarser mesh for this body, or leave the "
            "geometric stiffening out.")


def hex_gauss_gradients(model: SolidFEModel) -> tuple[Float[Array, "n_elements 8 3 8"], Float[Array, "n_elements 8"]]:
    """Cartesian gradients of the trilinear shape functions and quadrature weights at the 2x2x2 Gauss points.

    **Returns:** `(G, w)`: `G[e, g, a, n] = dN_n / dx_a` at Gauss point `g` of element `e`, and `w[e, g] = det J`
    (the Gauss weights are 1), from the node coordinates of `model` (pytree leaves).
    """
    nodes = model.element_dofs[:, 0::3] // 3
    xyz = model.coordinates[nodes]  # (n_e, 8, 3)
    grads, weights = [], []
    for point, w in gauss_points_2x2x2():
        _, dn = trilinear(*point)
        dn = jnp.asarray(dn, dtype=xyz.dtype)
        jac = jnp.einsum("in,enj->eij", dn, xyz)  # J[e, i, j] = d x_j / d xi_i
        grads.append(jnp.linalg.solve(jac, jnp.broadcast_to(dn, (xyz.shape[0],) + dn.shape)))
        weights.append(w * jnp.linalg.det(jac))
    return jnp.stack(grads, axis=1), jnp.stack(weights, axis=1)


def solid_stress_tensors(model: SolidFEModel, youngs, u, grads) -> Float[Array, "n_elements 8 3 3"]:
    """Stress tensors `sigma = E_e D B u_e` at the Gauss points, for a nodal displacement `u` `(n_dof,)`."""
    u_e = u[model.element_dofs].reshape(-1, 8, 3)  # (n_e, node, component)
    du = jnp.einsum("egan,enc->egca", grads, u_e)  # du_c / dx_a
    strain = jnp.stack([du[..., 0, 0], du[..., 1, 1], du[..., 2, 2], du[..., 1, 2] + du[..., 2, 1],
                        du[..., 0, 2] + du[..., 2, 0], du[..., 0, 1] + du[..., 1, 0]], axis=-1)
    s = youngs[:, None, None] * (strain @ jnp.asarray(isotropic(model.poisson)).T)  # Voigt xx yy zz yz xz xy
    return jnp.stack([jnp.stack([s[..., 0], s[..., 5], s[..., 4]], -1),
                      jnp.stack([s[..., 5], s[..., 1], s[..., 3]], -1),
                      jnp.stack([s[..., 4], s[..., 3], s[..., 2]], -1)], -2)


def solid_modal_geometric_stiffness(model: SolidFEModel, stresses, modes, grads, weights) -> Float[Array, "n_q n_q"]:
    """`Phi^T K_G(sigma) Phi` element by element, for Gauss-point stress tensors `(n_elements, 8, 3, 3)`."""
    phi_e = modes[model.element_dofs].reshape(-1, 8, 3, modes.shape[1])  # (n_e, node, component, q)
    grad_phi = jnp.einsum("egan,encq->egacq", grads, phi_e)  # d phi_c / dx_a
    return jnp.einsum("eg,egacq,egab,egbcr->qr", weights, grad_phi, stresses, grad_phi)


def solid_centrifugal_geometric_stiffness(model: SolidFEModel, youngs, densities, modes,
                                          fixed_dofs: tuple[int, ...]) -> Float[Array, "6 n_q n_q"]:
    """The six modal geometric stiffness matrices of the unit centrifugal load cases (module docstring).

    **Arguments:**
    - `model`: a hexahedral [`SolidFEModel`][] (H8 or H11); `youngs`, `densities`: `(n_elements,)` element values.
    - `modes`: `(n_dof, n_q)` the retained shape vectors `Phi`.
    - `fixed_dofs`: the supports of the static solves (the reference conditions of the modes); they must hold the
      body statically (six rigid motions removed), else `K_ff` is singular.

    **Returns:** `K_k = Phi^T K_G(sigma_k) Phi`, `(6, n_q, n_q)`, each symmetric, in the order of
    `angular_velocity_products` (this module): `K_geo(omega) = sum_k pi_k(omega) K_k`.
    """
    _check_hexahedral(model)
    fixed = np.unique(np.asarray(fixed_dofs, dtype=np.int64))
    if fixed.size == 0 or fixed.min() < 0 or fixed.max() >= model.n_dof:
        raise ValueError(f"fixed_dofs must name supports among the {model.n_dof} degrees of freedom (a body turning "
                         f"about its frame origin is held there, e.g. a clamped root); got {fixed_dofs!r}.")
    held = rigid_motions(model.mesh.nodes)[fixed]
    if np.linalg.matrix_rank(held, tol=1e-10 * np.max(np.abs(held))) < 6:
        raise ValueError("fixed_dofs do not hold the body: some rigid motion leaves every fixed degree of freedom at "
                         "rest, so the static pre-stress solve is singular. Hold at least three non-collinear nodes "
                         "(e.g. a clamped face) or the reference conditions of the body's modes.")
    free = np.setdiff1d(np.arange(model.n_dof), fixed)
    k = solid_dense_matrix(model, youngs, "stiffness")
    m = solid_dense_matrix(model, densities, "mass")
    loads = m @ unit_load_fields(model.coordinates).reshape(6, -1).T  # (n_dof, 6)
    u_f = jnp.linalg.solve(k[np.ix_(free, free)], loads[free])
    u = jnp.zeros((model.n_dof, 6), u_f.dtype).at[free].set(u_f)
    grads, weights = hex_gauss_gradients(model)
    return jnp.stack([
        solid_modal_geometric_stiffness(model, solid_stress_tensors(model, youngs, u[:, k_], grads), modes, grads,
                                        weights)
        for k_ in range(6)])
