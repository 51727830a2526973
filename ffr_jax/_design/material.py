"""Design variables -> element material properties (SIMP with the paper's density law, eq. 47)."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._checks import in_interval, positive

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

    def __check_init__(self):
        check_parameters(self)

    def youngs(self, x: ElementField) -> ElementField:
        """Element Young's moduli `E_e = x_e^p E0`, `(n_elements,)`."""
        return x**self.stiffness_penalty * self.youngs_modulus

    def densities(self, x: ElementField) -> ElementField:
        """Element mass densities (paper eq. 47), `(n_elements,)`."""
        low = self.mass_factor * x**self.mass_penalty * self.density
        return jnp.where(x < self.x_switch, low, x * self.density)


def check_parameters(material) -> None:
    """The SIMP parameters are finite and physical, or a `ValueError` that names the one that is not.

    `E0`, `rho0`, the penalties `p`, `q` and the mass factor `c` positive (a negative density or
    modulus makes `M` or `K` indefinite; a non-positive penalty turns the interpolation upside
    down), `x_switch` in `(0, 1]` and `x_min` in `(0, 1)` (at `x_min = 0` a void element has no
    stiffness and `K` is singular).
    """
    name = type(material).__name__
    positive(material.youngs_modulus, f"{name}(youngs_modulus=...)", "It is the solid's Young's modulus E0 in Pa "
             "(default 0.5e11).")
    positive(material.density, f"{name}(density=...)", "It is the solid's mass density rho0 in kg/m^3 (default 8750); "
             "a non-positive density makes the mass matrix indefinite.")
    positive(material.stiffness_penalty, f"{name}(stiffness_penalty=...)", "It is the SIMP exponent p of "
             "E = x^p E0 (default 3; 1 is no penalisation).")
    positive(material.mass_penalty, f"{name}(mass_penalty=...)", "It is the exponent q of the low-density mass law "
             "rho = c x^q rho0 (default 6).")
    positive(material.mass_factor, f"{name}(mass_factor=...)", "It is the factor c of the low-density mass law "
             "rho = c x^q rho0 (default 1e5 = x_switch^(1 - q), continuous at x_switch).")
    in_interval(material.x_switch, f"{name}(x_switch=...)", 0.0, 1.0, low_open=True,
                advice="It is the density below which the low-density mass law applies (default 0.1).")
    in_interval(material.x_min, f"{name}(x_min=...)", 0.0, 1.0, low_open=True, high_open=True,
                advice="It is the smallest density (default 0.01); at 0 a void element has no stiffness and K is "
                       "singular.")
