"""qp-relaxed stress modes: the stress of the solid material scaled by `x_e^s`, so that the stress of a
vanishing element vanishes with it (the singular optimum of stress-constrained SIMP, Bruggi 2008)."""

import jax

from .._design.designed_body import DesignedBody
from .._design.geometric_stiffness import element_stresses, gauss_gradients


def relaxed_stress_modes(body: DesignedBody, x, relaxation=0.5):
    """Relaxed plane stresses of each shape vector of the body's modal basis at design `x`.

    `sigma_hat_k = x_e^s E0 D B_g phi_k` at the 2x2 Gauss points of every element: the stress the
    solid material would carry at the element's strain (`E0 D B_g phi_k`, the "microscopic" stress
    of SIMP), times `x_e^s`. With `0 < s` the stress of an element with `x_e -> 0` tends to zero, so
    void elements do not dominate an aggregated stress measure (the qp-relaxation of Bruggi 2008 with
    `s = p - q`; `s = p` gives the macroscopic stress of [`stress_modes`][], `s = 0` the unrelaxed
    solid stress). The modes themselves are those of the design (`K(x)`, `M(x)`).

    **Arguments:**
    - `body`: the [`DesignedBody`][]; `x`: its `(n_design,)` design.
    - `relaxation`: the exponent `s >= 0` (default 0.5, i.e. `p = 3`, `q = 2.5` in Bruggi's terms).

    **Returns:** `(n_elements, 4, 3, n_q)`: `(sigma_xx, sigma_yy, tau_xy)` per Gauss point and shape vector.

    > M. Bruggi, "On an alternative approach to stress constraints relaxation in topology
    > optimization", Struct. Multidisc. Optim. 36 (2008) 125-141.
    """
    densities = body.element_densities(x)
    scale = densities**relaxation * body.material.youngs_modulus
    modes = body.modes(x).modes
    grads, _ = gauss_gradients(body.model)
    return jax.vmap(lambda u: element_stresses(body.model, scale, u, grads), in_axes=1, out_axes=-1)(modes)
