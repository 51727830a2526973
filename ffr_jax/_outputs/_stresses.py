"""Stresses in a flexible body from stress modes: `sigma(t) = sum_k sigma_k q_k(t)` (linear elasticity
in the floating frame: the elastic displacement is `Phi q`)."""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._design.designed_body import DesignedBody
from .._design.geometric_stiffness import element_stresses, gauss_gradients


def stress_modes(body: DesignedBody, x):
    """Plane stresses of each shape vector of the body's modal basis at design `x`.

    `sigma_k = E_e D B_g phi_k` at the 2x2 Gauss points of every element (plane stress; `D` for
    `E = 1`, `E_e` the SIMP stiffness of the element), computed once per design; the stresses
    along the motion are `sigma(t) = sum_k sigma_k q_k(t)`.

    **Returns:** `(n_elements, 4, 3, n_q)`: `(sigma_xx, sigma_yy, tau_xy)` per Gauss point and shape vector.
    """
    youngs, _ = body.element_values(x)
    modes = body.modes(x).modes
    grads, _ = gauss_gradients(body.model)
    return jax.vmap(lambda u: element_stresses(body.model, youngs, u, grads), in_axes=1, out_axes=-1)(modes)


def von_mises(sigma):
    """Plane-stress von Mises stress `sqrt(sxx^2 + syy^2 - sxx syy + 3 txy^2)` of `(..., 3)` stresses."""
    sxx, syy, txy = sigma[..., 0], sigma[..., 1], sigma[..., 2]
    return jnp.sqrt(sxx**2 + syy**2 - sxx * syy + 3.0 * txy**2)


def _n_static(designed: DesignedBody) -> int:
    """Number of static (interface) shape vectors of the body's basis, from its structure."""
    return jax.eval_shape(lambda: designed.modes(designed.initial_design(0.5))).modes.shape[1] - designed.n_modes


@eqx.filter_jit
def modal_stresses(modes_of_stress, q):
    """`sigma = sum_k sigma_k q_k`: `(..., n_elements, 4, 3)` from stress modes `(n_elements, 4, 3, n_q)`
    and modal coordinates `(..., n_q)`."""
    return jnp.einsum("egck,...k->...egc", modes_of_stress, q)


def stresses(case, trajectory, x, body: int = 0):
    """Plane stresses of a case's designed body at the output times of `trajectory`, `(n_t, n_elements, 4, 3)`.

    `sigma(t) = sum_k sigma_k q_k(t)` with the stress modes of design `x` ([`stress_modes`][]) and the
    modal coordinates `q` of scene body `body` (default 0, the rod of the rod cases); [`von_mises`][]
    of the result gives the von Mises stress per Gauss point, its maximum over axis 0 the peak per
    Gauss point over time.

    **Arguments:**
    - `case`: a case with one designed body; `trajectory`: [`simulate`][]`(case, x, ts=...)`; `x`: its design.
    - `body`: the index of the designed body in the scene.
    """
    from .._dynamics._case import Case

    if not isinstance(case, Case):
        raise ValueError(f"ffr_jax.stresses takes a case with its design, got {type(case).__name__}.")
    designed = case.design
    scene = case.problem.scene
    if not 0 <= body < len(scene.bodies) or scene.sizes[body] != 3 + designed.reduction.n_modes + _n_static(designed):
        raise ValueError(f"Scene body {body} is not the designed body of this case (bodies "
                         f"{[b.name for b in scene.bodies]}); give its index as body=.")
    o = scene.offsets[body]
    q = trajectory.positions[:, o + 3 : o + scene.sizes[body]]
    return modal_stresses(stress_modes(designed, x), q)
