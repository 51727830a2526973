"""Design variables → element material properties (SIMP, paper eq. 47)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import design_array, design_values, is_traced
from ._design.material import check_parameters
from ._errors import DesignError, error_if
from ._fe import RodMesh
from ._typing import Design, ElementField


class SIMP(eqx.Module):
    """Solid isotropic material with penalisation, with the modified density law of paper eq. 47.

    `rho_e = c x_e^q rho0` for `x_e < x_switch`, `rho_e = x_e rho0` otherwise, and `E_e = x_e^p E0`.
    With `c = x_switch^(1 - q)` the density is continuous at `x_switch`; low densities get a tiny
    mass so that void regions do not produce spurious local modes.
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
        """Element Young's moduli `E_e = x_e^p E0`."""
        return x**self.stiffness_penalty * self.youngs_modulus

    def densities(self, x: ElementField) -> ElementField:
        """Element mass densities, paper eq. 47."""
        low = self.mass_factor * x**self.mass_penalty * self.density
        return jnp.where(x < self.x_switch, low, x * self.density)


class RodDesign(eqx.Module):
    """Layout of the design vector over a rod mesh (REFERENCE_CASE §1).

    The first and last element columns are solid interfaces (`x = 1`) and carry no design
    variable. The design vector has `ny (nx - 2)` entries, row-major: element `(i, j)` is
    `x.reshape(ny, nx - 2)[j, i - 1]`.
    """

    mesh: RodMesh
    material: SIMP

    @property
    def n_design(self) -> int:
        return self.mesh.ny * (self.mesh.nx - 2)

    def initial_design(self, value: float = 0.5) -> Design:
        """A uniform design `x_e = value` (flat, in design order)."""
        if not self.material.x_min <= float(value) <= 1.0:
            raise ValueError(f"Design value {value} lies outside [x_min, 1] = [{self.material.x_min}, 1].")
        return jnp.full((self.n_design,), float(value))

    def check(self, x) -> Design:
        """Validate a design and return it as float64: dtype and shape at trace time, values (NaN,
        inf, bounds `[x_min, 1]`) at once when `x` is concrete, else at run time (`error_if`).

        Raises [`DesignError`][] (a `ValueError`): complex numbers are refused, integers and float32
        are converted to float64 (so that the gradient is float64 too).
        """
        x = design_array(x)
        if x.shape != (self.n_design,):
            raise DesignError(
                f"Design vector has shape {x.shape}, expected ({self.n_design},) = ny * (nx - 2) for the "
                f"{self.mesh.nx} x {self.mesh.ny} mesh (interface columns carry no design variable). "
                "Use case.initial_design(value) for a valid vector."
            )
        lo, hi = self.material.x_min, 1.0
        if not is_traced(x):
            design_values(x, lo)
            return x
        x = error_if(x, ~jnp.all(jnp.isfinite(x)), "Design vector contains NaN or inf; every density must be a "
                     f"finite number in [x_min, 1] = [{lo}, 1].", DesignError)
        return error_if(
            x,
            jnp.any((x < lo) | (x > hi)),
            f"Design densities must lie in [x_min, 1] = [{lo}, {hi}]; clip or project the design first.",
            DesignError,
        )

    def element_densities(self, x: Design) -> ElementField:
        """Full element field `(n_elements,)` in flat element order `j nx + i`, interfaces solid."""
        nx, ny = self.mesh.nx, self.mesh.ny
        inner = x.reshape(ny, nx - 2)
        ones = jnp.ones((ny, 1), dtype=x.dtype)
        return jnp.concatenate([ones, inner, ones], axis=1).ravel()

    def design_centres(self) -> np.ndarray:
        """Centres `(n_design, 2)` of the design elements, in design order (for plots and filters)."""
        nx, ny = self.mesh.nx, self.mesh.ny
        return self.mesh.element_centres().reshape(ny, nx, 2)[:, 1:-1].reshape(-1, 2)
