"""An objective of the whole motion: an integral and a terminal term."""

import equinox as eqx

from ._base import AbstractIntegrand


class Objective(eqx.Module):
    """`psi = G(t1, y_r(t1), z_r(t1), p) + int_{t0}^{t1} F(t, y_r, z_r, p) dt`.

    **Fields:**
    - `integrand`: `F`, or `None` for no integral part.
    - `terminal`: `G`, or `None` for no terminal part.

    Either may be any [`AbstractIntegrand`][] ([`Compliance`][], [`KineticEnergy`][],
    [`MarkerTracking`][], [`FunctionIntegrand`][], sums and weighted terms).
    """

    integrand: AbstractIntegrand | None = None
    terminal: AbstractIntegrand | None = None

    def __check_init__(self):
        for name in ("integrand", "terminal"):
            term = getattr(self, name)
            if term is not None and not isinstance(term, AbstractIntegrand):
                raise ValueError(
                    f"Objective.{name} must be an objective term (e.g. ffr_jax.KineticEnergy(), "
                    f"ffr_jax.FunctionIntegrand(fn)) or None, got {type(term).__name__}."
                )
        if self.integrand is None and self.terminal is None:
            raise ValueError("An Objective needs an integrand, a terminal term, or both.")


def as_objective(objective) -> Objective:
    """An [`Objective`][] from an `Objective`, a term (taken as the integrand) or a function."""
    if isinstance(objective, Objective):
        return objective
    if isinstance(objective, AbstractIntegrand):
        return Objective(integrand=objective)
    if callable(objective):
        from ._function import FunctionIntegrand

        return Objective(integrand=FunctionIntegrand(objective))
    raise ValueError(
        f"objective must be an ffr_jax.Objective, an objective term or a function, got {type(objective).__name__}."
    )
