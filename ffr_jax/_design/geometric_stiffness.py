"""Geometric (stress) stiffness of a finite element body under the centrifugal load of a unit rotation rate.

A body spinning at rate `omega` about its frame origin carries, quasi-statically, the body load
`rho omega^2 c` (per unit volume, `c` the undeformed position in the body frame). Its consistent
nodal load is `omega^2 M c` (exact: `c` is linear, so the bilinear shape functions interpolate it
exactly). The static displacement `u_1` of the unit load solves

`K_ff u_1 = (M c)_f`

with the degrees of freedom of the reference conditions held (for the rod the hinged supports
`u_x(A)`, `u_y(A)`, `u_y(B)`, REFERENCE_CASE §2), and the element stresses at the 2x2 Gauss points
are `sigma_1 = E_e D B u_1` (plane stress, `D` for `E = 1`, the bilinear strains of the nodal
field). The geometric stiffness of a stress field `sigma` (the second-order strain energy of the
pre-stress) is, per element and for each displacement component separately,

`K_G,e = t sum_g (dN/dxy)_g^T S_g (dN/dxy)_g det(J_g) w_g`,  `S = [[sigma_xx, tau_xy], [tau_xy, sigma_yy]]`,

and its modal projection `K_geo = Phi^T K_G(sigma_1) Phi` (element by element; the global `K_G` is
never formed) is the stiffening matrix per unit `omega^2`. Every step is a differentiable function
of the element values and the modes, so `K_geo(x)` carries design gradients. The shape-function
gradients are computed from the node coordinates of the [`FEModel`][] (pytree leaves), so any
quadrilateral mesh works; the static solve is dense (up to `MAX_DENSE_SOLVE_DOF` degrees of
freedom).

!!! cite "References"
    R. D. Cook, D. S. Malkus, M. E. Plesha, R. J. Witt, *Concepts and Applications of Finite
    Element Analysis*, 4th ed., Wiley (2002), §18.2 (geometric stiffness of plane elements).

    O. Wallrapp, "Standardization of flexible body modeling in multibody system codes, Part I",
    Mech. Struct. Mach. 22 (1994) 283–304 (geometric stiffening from unit load cases).
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .assembly import FEModel
from .element.base import bilinear, gauss_points_2x2, plane_stress

# Largest mesh (degrees of freedom) whose centrifugal pre-stress is solved with a dense K_ff
# (4,000 dofs: a 128 MB matrix and a second of LAPACK on one core).
MAX_DENSE_SOLVE_DOF = 4000


def gauss_gradients(model: FEModel) -> tuple[Float[Array, "n_elements 4 2 4"], Float[Array, "n_elements 4"]]:
    """Cartesian shape-function gradients and quadrature weights at the 2x2 Gauss points of every element.

    **Returns:** `(G, w)`: `G[e, g, a, n] = dN_n / dx_a` at Gauss point `g` of element `e`, and
    `w[e, g] = t det J` (the Gauss weights are 1), from the node coordinates of `model`.
    """
    nodes = model.element_dofs[:, 0::2] // 2
    xy = model.coordinates[nodes]  # (n_e, 4 nodes, 2)
    grads, weights = [], []
    for (xi, eta), w in gauss_points_2x2():
        _, dn = bilinear(xi, eta)
        dn = jnp.asarray(dn, dtype=xy.dtype)
        jac = jnp.einsum("in,enj->eij", dn, xy)  # J[e, i, j] = d x_j / d xi_i
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        inv = jnp.stack([jnp.stack([jac[:, 1, 1], -jac[:, 0, 1]], -1),
                         jnp.stack([-jac[:, 1, 0], jac[:, 0, 0]], -1)], 1) / det[:, None, None]
        grads.append(jnp.einsum("eai,in->ean", inv, dn))
        weights.append(w * model.thickness * det)
    return jnp.stack(grads, axis=1), jnp.stack(weights, axis=1)


def element_stresses(model: FEModel, youngs, u, grads) -> Float[Array, "n_elements 4 3"]:
    """Plane stresses `(sigma_xx, sigma_yy, tau_xy)` at the 2x2 Gauss points, `sigma = E_e D B_g u_e`."""
    u_e = u[model.element_dofs].reshape(-1, 4, 2)  # (n_e, node, component)
    du = jnp.einsum("egan,enc->egca", grads, u_e)  # du_c / dx_a
    strain = jnp.stack([du[..., 0, 0], du[..., 1, 1], du[..., 0, 1] + du[..., 1, 0]], axis=-1)
    return youngs[:, None, None] * (strain @ jnp.asarray(plane_stress(model.poisson)).T)


def modal_geometric_stiffness(model: FEModel, stresses, modes, grads, weights) -> Float[Array, "n_q n_q"]:
    """`Phi^T K_G(sigma) Phi` element by element, for Gauss-point stresses `(n_elements, 4, 3)`."""
    sxx, syy, sxy = stresses[..., 0], stresses[..., 1], stresses[..., 2]
    tensor = jnp.stack([jnp.stack([sxx, sxy], -1), jnp.stack([sxy, syy], -1)], -2)  # (n_e, g, 2, 2)
    phi_e = modes[model.element_dofs].reshape(-1, 4, 2, modes.shape[1])  # (n_e, node, component, q)
    grad_phi = jnp.einsum("egan,encq->egacq", grads, phi_e)  # d phi_c / dx_a
    return jnp.einsum("eg,egacq,egab,egbcr->qr", weights, grad_phi, tensor, grad_phi)


def centrifugal_geometric_stiffness(model: FEModel, youngs, densities, modes,
                                    fixed_dofs: tuple[int, ...]) -> Float[Array, "n_q n_q"]:
    """Modal geometric stiffness per unit `omega^2` of a rotation about the frame origin (module docstring).

    **Arguments:**
    - `model`: the [`FEModel`][]; `youngs`, `densities`: `(n_elements,)` element values.
    - `modes`: `(n_dof, n_q)` the retained shape vectors `Phi`.
    - `fixed_dofs`: the supports of the static solve (the reference conditions of the modes).

    **Returns:** `K_geo = Phi^T K_G(sigma_1) Phi`, `(n_q, n_q)`, symmetric.
    """
    if model.n_dof > MAX_DENSE_SOLVE_DOF:
        raise ValueError(
            f"Geometric stiffening solves the centrifugal pre-stress with a dense K: the mesh has {model.n_dof} "
            f"degrees of freedom, above the limit of {MAX_DENSE_SOLVE_DOF}. Use a coarser mesh for this body, or "
            "leave GeometricStiffening out of the scene."
        )
    free = np.setdiff1d(np.arange(model.n_dof), np.asarray(fixed_dofs, dtype=np.int64))
    k = model.stiffness(youngs).todense()
    load = model.mass(densities) @ model.coordinates.ravel()
    u_f = jnp.linalg.solve(k[np.ix_(free, free)], load[free])
    u = jnp.zeros(model.n_dof, u_f.dtype).at[free].set(u_f)
    grads, weights = gauss_gradients(model)
    return modal_geometric_stiffness(model, element_stresses(model, youngs, u, grads), modes, grads, weights)
