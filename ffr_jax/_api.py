"""Top-level functions: the objective of a case and its gradient by any sensitivity method."""

import diffrax

from ._case import FlexibleRodCase
from ._simulate import Trajectory, simulate
from ._typing import Design


def simulate_case(case: FlexibleRodCase, x: Design, *, rtol: float = 1e-10, atol: float = 1e-12,
                  solver: diffrax.AbstractSolver | None = None, ts=None, dense: bool = False,
                  max_steps: int = 1_000_000, adjoint: diffrax.AbstractAdjoint | None = None) -> Trajectory:
    """Simulate a case for design `x` with its objective integrated along (see [`simulate`][])."""
    return simulate(
        case.model, case.scene(x), case.t0, case.t1, case.y_r0, case.z_r0,
        integrand=case.integrand, solver=solver, rtol=rtol, atol=atol, ts=ts, dense=dense,
        max_steps=max_steps, adjoint=adjoint, jump_ts=case.jump_ts,
    )


def objective(case: FlexibleRodCase, x: Design, *, rtol: float = 1e-10, atol: float = 1e-12,
              solver: diffrax.AbstractSolver | None = None, max_steps: int = 1_000_000):
    """`psi(x) = int_{t0}^{t1} F(t, y_r, p(x)) dt` of a case (REFERENCE_CASE §4: the integral compliance).

    **Arguments:**
    - `case`: e.g. `ffr_jax.cases.slider_crank()`; `x`: `(n_design,)` densities in `[x_min, 1]`.
    - `rtol`, `atol`: forward tolerances (the paper's 1e-10 / 1e-12 by default).
    - `solver`: diffrax solver (default `Tsit5()`).

    **Returns:** scalar `psi`.
    """
    return simulate_case(case, x, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps).psi
