"""The six unit-case geometric stiffness matrices of a planar finite element body lifted into space.

A planar body lifted to `z = 0` ([`lifted_body_data`][]) has in-plane modes only. Of the six unit centrifugal load
fields of `ffr_jax._design.solid_geometric_stiffness` at nodes with `c_z = 0`,

`f_1 = (0, c_y, 0)`, `f_2 = (c_x, 0, 0)`, `f_3 = (c_x, c_y, 0)`, `f_4 = -(0, 0, c_y)`, `f_5 = -(0, 0, c_x)`,
`f_6 = -(c_y, c_x, 0)`,

four are in-plane and give a plane-stress pre-stress (solved as the planar `GeometricStiffening`'s, with the same
supports); `f_4` and `f_5` load the plate across its plane, which bends it with stresses odd through the thickness:
their work on in-plane (thickness-uniform) mode shapes vanishes, so `K_4 = K_5 = 0`. `K_3` is the planar `K_geo`
(a spin about `z`). Differentiable in the element values and the modes, like the planar one.
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._design.geometric_stiffness import (MAX_DENSE_SOLVE_DOF, element_stresses, gauss_gradients,
                                           modal_geometric_stiffness)
from ._lift import lifted_body_data


def lifted_centrifugal_geometric_stiffness(model, youngs, densities, modes,
                                           fixed_dofs: tuple[int, ...]) -> Float[Array, "6 n_q n_q"]:
    """`K_k = Phi^T K_G(sigma_k) Phi` `(6, n_q, n_q)` of the lifted planar body (module docstring), in the order of
    `angular_velocity_products`.

    **Arguments:** the planar `FEModel` `model`; `youngs`, `densities`: `(n_elements,)`; `modes`: `(n_dof, n_q)`
    in-plane shape vectors; `fixed_dofs`: the supports (the modes' reference conditions).
    """
    if model.n_dof > MAX_DENSE_SOLVE_DOF:
        raise ValueError(
            f"Geometric stiffening solves the centrifugal pre-stress with a dense K: the mesh has {model.n_dof} "
            f"degrees of freedom, above the limit of {MAX_DENSE_SOLVE_DOF}. Use a coarser mesh for this body, or "
            "leave SpatialGeometricStiffening out of the scene.")
    c = model.coordinates
    x, y, zero = c[:, 0], c[:, 1], jnp.zeros_like(c[:, 0])
    fields = jnp.stack([jnp.stack(f, -1).ravel() for f in ((zero, y), (x, zero), (x, y), (-y, -x))], axis=1)
    free = np.setdiff1d(np.arange(model.n_dof), np.asarray(fixed_dofs, dtype=np.int64))
    k = model.stiffness(youngs).todense()
    loads = model.mass(densities) @ fields
    u_f = jnp.linalg.solve(k[np.ix_(free, free)], loads[free])
    u = jnp.zeros((model.n_dof, 4), u_f.dtype).at[free].set(u_f)
    grads, weights = gauss_gradients(model)
    in_plane = [modal_geometric_stiffness(model, element_stresses(model, youngs, u[:, i], grads), modes, grads, weights)
                for i in range(4)]
    none = jnp.zeros_like(in_plane[0])
    return jnp.stack([in_plane[0], in_plane[1], in_plane[2], none, none, in_plane[3]])


def lifted_body_data_and_geometric_stiffness(body, x, stiffening: bool):
    """`(lifted body data, K_k (6, n_q, n_q) or None)` of a planar `DesignedBody` for design `x`, from one modal
    reduction (`stiffening` static)."""
    youngs, densities = body.element_values(x)
    basis = body.reduction(body.model, youngs, densities)
    k, m = body.model.stiffness(youngs), body.model.mass(densities)
    data = lifted_body_data(body.model, k, m, basis.modes, body.markers)
    if not stiffening:
        return data, None
    return data, lifted_centrifugal_geometric_stiffness(body.model, youngs, densities, basis.modes, body.fixed_dofs)
