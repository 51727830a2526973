"""The p-norm integrand of the relaxed von Mises stress of a flexible body over its Gauss points."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._base import AbstractIntegrand


def von_mises_squared(sigma):
    """`sxx^2 + syy^2 - sxx syy + 3 txy^2` of `(..., 3)` plane stresses: the squared von Mises stress,
    smooth at zero stress (the von Mises stress itself is not differentiable there)."""
    sxx, syy, txy = sigma[..., 0], sigma[..., 1], sigma[..., 2]
    return sxx**2 + syy**2 - sxx * syy + 3.0 * txy**2


def _is_number(value) -> bool:
    """A real number: a Python or NumPy scalar or a concrete 0-d array of a real, non-boolean dtype."""
    if isinstance(value, (bool, np.bool_)) or isinstance(value, jax.core.Tracer):
        return False
    if isinstance(value, (int, float, np.floating, np.integer)):
        return True
    return (isinstance(value, (np.ndarray, jax.Array)) and np.ndim(value) == 0
            and np.issubdtype(np.result_type(value), np.number) and not np.iscomplexobj(value))


def check_stress_options(limit, power, relaxation=None, where: str = "StressMeasure") -> tuple[float, float]:
    """`(limit, power)` as floats, or a `ValueError` saying what is wrong (checked before anything is traced)."""
    if not _is_number(limit) or not np.isfinite(float(limit)) or not float(limit) > 0:
        raise ValueError(f"{where}: the stress limit must be a positive finite number (in Pa, like the material's "
                         f"Young's modulus), got {limit!r}.")
    if isinstance(power, bool) or not isinstance(power, (int, float)) or not np.isfinite(power) or not power >= 2:
        raise ValueError(f"{where}: the aggregation power must be a number >= 2 (the measure is "
                         f"(sigma_vm^2)^(power/2), differentiable at zero stress for power >= 2; 8 is usual), "
                         f"got {power!r}.")
    if relaxation is not None and (isinstance(relaxation, bool) or not isinstance(relaxation, (int, float))
                                   or not 0 <= relaxation <= 10):
        raise ValueError(f"{where}: the relaxation exponent s of sigma_hat = x^s sigma_solid must be a number in "
                         f"[0, p] (0.5 is usual; 0: no relaxation), got {relaxation!r}.")
    return float(limit), float(power)


class StressMeasure(AbstractIntegrand):
    """`F = sum_{e,g} (sigma_vm_hat_eg(t) / sigma_lim)^P`: the `P`-th power sum of the relaxed von Mises
    stress over the Gauss points of body `body`.

    `sigma_hat(t) = sum_k sigma_hat_k q_k(t)` from the body's relaxed stress modes
    ([`relaxed_stress_modes`][], `(n_elements, 4, 3, n_q)`, an array leaf computed from the design),
    so that `psi = int F dt` and the aggregated stress

    `sigma_PN = sigma_lim (psi / (t1 - t0))^(1/P)`

    is the `P`-norm of the stress over the Gauss points and the (time-averaged) motion: it tends to
    the peak from above over the points and from below over time as `P` grows (see
    [`aggregated_stress`][], which forms it with its design gradient). The term is written with
    `(sigma_vm^2 / sigma_lim^2)^(P/2)`, smooth at zero stress.

    **Arguments:**
    - `stress_modes`: `(n_elements, 4, 3, n_q)` relaxed stress modes of the body's design.
    - `body`: the index of the flexible body in the scene.
    - `limit`: `sigma_lim` > 0 (Pa), the stress the measure is normalised by.
    - `power`: `P >= 2` (default 8).
    """

    stress_modes: Float[Array, "n_elements 4 3 n_q"]
    body: int = eqx.field(static=True)
    limit: Float[Array, ""]
    power: float = eqx.field(static=True)

    def __init__(self, stress_modes, body: int, limit, power=8.0):
        # The limit is an array leaf, not a static value: a compiled program takes a new limit as an input instead of
        # compiling again. Traced (an argument of a compiled program), it was checked where it entered.
        if isinstance(limit, jax.core.Tracer):
            _, self.power = check_stress_options(1.0, power)
            self.limit = limit
        else:
            limit, self.power = check_stress_options(limit, power)
            self.limit = jnp.asarray(limit, dtype=float)
        if np.ndim(stress_modes) != 4 or np.shape(stress_modes)[1:3] != (4, 3):
            raise ValueError(f"StressMeasure needs stress modes of shape (n_elements, 4, 3, n_q) (see "
                             f"ffr_jax.relaxed_stress_modes), got {np.shape(stress_modes)}.")
        if isinstance(body, bool) or not isinstance(body, (int, np.integer)) or body < 0:
            raise ValueError(f"StressMeasure: body is the index of the flexible body in the scene, got {body!r}.")
        self.stress_modes = stress_modes
        self.body = int(body)

    def __call__(self, t, y_r, z_r, scene):
        del t, z_r
        n_q = self.stress_modes.shape[-1]
        if self.body >= len(scene.bodies) or scene.sizes[self.body] != 3 + n_q:
            raise ValueError(f"StressMeasure: scene body {self.body} does not have the {n_q} shape vectors of the "
                             f"stress modes (bodies {[b.name for b in scene.bodies]}, sizes {scene.sizes}); give "
                             "the index of the designed body.")
        q = scene.body_coordinates(self.body, y_r)[3:]
        sigma = jnp.einsum("egck,k->egc", self.stress_modes, q)
        return jnp.sum((von_mises_squared(sigma) / self.limit**2) ** (self.power / 2))
