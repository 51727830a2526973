"""Design variables -> element material properties (SIMP with the paper's density law, eq. 47)."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

ElementField = Float[Array, " n_elements"]


class SIMP(eqx.Module):
    """Solid isotropic material with penalisation, with the modified density law of paper eq. 47.

    `E_e = x_e^p E0`;  `rho_e = c x_e^q rho0` for `x_e < x_switch`, `rho_e = x_e rho0` otherwise.
    With `c = x_switch^(1 - q)` (the default `c = 1e5`, `q = 6`, `x_switch = 0.1`) the density is
    continuous at `x_switch`; low densities get a tiny mass so that void regions do not produce
    spurious local modes. Defaults: REFERENCE_CASE §1 (`E0 = 0.5e11`, `rho0 = 8750`, `p = 3`,
    `x_min = 0.01`).
    """

    youngs_modulus: float = eqx.field(static=True, default=0.5e11)
    density: float = eqx.field(static=True, default=8750.0)
    stiffness_penalty: float = eqx.field(static=True, default=3.0)
    mass_penalty: float = eqx.field(static=True, default=6.0)
    mass_factor: float = eqx.field(static=True, default=1e5)
    x_switch: float = eqx.field(static=True, default=0.1)
    x_min: float = eqx.field(static=True, default=0.01)

    def youngs(self, x: ElementField) -> ElementField:
        """Element Young's moduli `E_e = x_e^p E0`, `(n_elements,)`."""
        return x**self.stiffness_penalty * self.youngs_modulus

    def densities(self, x: ElementField) -> ElementField:
        """Element mass densities (paper eq. 47), `(n_elements,)`."""
        low = self.mass_factor * x**self.mass_penalty * self.density
        return jnp.where(x < self.x_switch, low, x * self.density)
