"""The optimiser's defaults and its failures, as a user meets them: the default MMA on a small case of the
slider-crank family, the same move limit in Python and the CLI, and an error raised inside the compiled
step reported with the step, the reason and what to change (not XLA's or equinox's traceback)."""

import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._errors import SimulationError, error_if
from ffr_jax._dynamics._model import _NOT_CONVERGED
from ffr_jax._app._cli_optimize import _DEFAULTS as CLI_DEFAULTS
from helpers import small_case

VOLUME = 0.5
ITERATIONS = 8


def test_mma_move_limit_is_the_same_in_python_and_the_cli():
    assert fj.MMA().move == CLI_DEFAULTS["mma_move"] == 0.2


def test_default_mma_lowers_psi_with_the_volume_held():
    # The README's setting: a density filter of 1.5 elements, the volume an upper bound, MMA's defaults.
    case = small_case()
    filt = fj.DensityFilter(case.design, radius=1.5)
    fun = fj.make_objective(case, "adjoint", filter=filt, rtol=1e-6, atol=1e-12)
    volume = fj.VolumeConstraint(VOLUME, x_min=case.material.x_min, filter=filt)
    result = fj.optimize(fun, case.initial_design(VOLUME), fj.MMA(case.material.x_min), volume,
                         iterations=ITERATIONS, progress=False)
    psi = result.history.value
    # Every step ran (none met a design it could not simulate). psi is not monotone in the densities
    # (README: mass adds inertia), and MMA's first steps move material out of the inner rows, raising psi
    # by a few per cent; within eight steps it settles 2 % below the uniform start (measured: 0.977). The
    # bound 0.99 asks for a 1 % decrease, four orders of magnitude above the solves' relative error (rtol 1e-6).
    assert result.history.steps == ITERATIONS and result.back_offs == 0, "no step was redone"
    assert psi[-1] < 0.99 * psi[0], f"psi per step / psi_0: {psi / psi[0]}"
    # The volume bound holds at every step's design and at the end, to MMA's subproblem tolerance
    # (epsimin 1e-7 on the normalised constraint; 1e-6 leaves a margin).
    assert np.all(result.history.constraint_values <= 1e-6), result.history.constraint_values
    assert result.feasible and result.constraints[0] <= 1e-6


def _stiff_until(limit):
    """`x -> (psi, grad)` with psi = -sum(x) (every step raises x by the move limit) that fails inside the
    compiled program as Newton's method does once a density passes `limit`."""

    def fun(x):
        psi = error_if(-jnp.sum(x), jnp.any(x > limit), _NOT_CONVERGED, SimulationError)
        return psi, -jnp.ones_like(x)

    return fun


def test_a_step_too_large_is_redone_with_half_the_move(tmp_path):
    # psi = -sum(x) moves every density up by the move limit: 0.5 -> 0.7 (update of step 0) -> 0.9 (step 1).
    # Step 2 cannot simulate 0.9 > 0.85: step 1's update is redone with move 0.1, to 0.8, and the run goes on
    # with its own 0.2: 0.8 -> 1.0 fails, 0.9 (move 0.1) fails, 0.85 (0.05) holds.
    with pytest.warns(fj.StepBackOffWarning) as caught:
        result = fj.optimize(_stiff_until(0.85), jnp.full(6, 0.5), fj.MMA(), iterations=4,
                             directory=tmp_path / "run", checkpoint_every=1, progress=False)
    assert [str(w.message).split(":")[0] for w in caught] == ["Step 2", "Step 3", "Step 3"]
    assert [str(w.message).rsplit(" ", 1)[1] for w in caught] == ["0.1.", "0.1.", "0.05."]
    assert result.back_offs == 3 and result.history.steps == 4
    # Every evaluated design could be simulated (x <= 0.85, psi = -6 x), and the redone updates moved by half
    # and a quarter of the first: MMA's move bound is active in each update, its step stopping within 1 % of
    # it (the 0.001 and 1e-5 terms of Svanberg's p0, q0 keep the subproblem's optimum just inside the bound;
    # measured 0.198 of 0.2), so the ratios hold to 2 %.
    assert np.all(-result.history.value / 6 <= 0.85)
    change = result.history.change
    np.testing.assert_allclose(change[1:3] / change[0], [0.5, 0.25], rtol=0.02, err_msg="halved move limits")
    log = (tmp_path / "run" / "log.csv").read_text().splitlines()
    assert len(log) == 5, "the log rewritten with the redone rows, one per step"
    np.testing.assert_allclose([float(row.split(",")[3]) for row in log[1:]], result.history.change, rtol=1e-15)


def test_a_design_that_cannot_be_simulated_stops_the_run_with_the_step_and_advice(tmp_path):
    # With a limit below every redone update (0.7 + 0.1 / 2^k > 0.7), step 2 stops the run after four back-offs.
    with pytest.warns(fj.StepBackOffWarning), pytest.raises(SimulationError) as caught:
        fj.optimize(_stiff_until(0.7 + 1e-9), jnp.full(6, 0.5), fj.MMA(), iterations=5,
                    directory=tmp_path / "run", checkpoint_every=1, progress=False)
    message = str(caught.value)
    assert message.startswith("Step 2 of the optimisation stopped: the design could not be simulated.")
    assert "update of step 1" in message and "too large" in message and "move" in message
    assert "cannot assemble" in message, "the solver's own reason is kept"
    assert "redone 4 times" in message
    assert "filter_jit" not in message and "Traceback" not in message and message.count("\n") == 0
    assert (tmp_path / "run" / "log.csv").read_text().count("\n") == 3, "header and the two complete steps"


def test_adam_stops_at_once_with_the_step_and_advice():
    import optax

    def fun(x):  # psi = -x_0: gradient descent raises x_0 (0.5 -> 0.583 after the volume projection)
        psi = error_if(-x[0], x[0] > 0.55, _NOT_CONVERGED, SimulationError)
        return psi, -jnp.zeros_like(x).at[0].set(1.0)

    with pytest.raises(SimulationError, match=r"^Step 1 of the optimisation stopped: .* too large"):
        fj.optimize(fun, jnp.full(6, 0.5), optax.sgd(0.1), fj.VolumeConstraint(0.5, x_min=0.01), iterations=3,
                    progress=False)


def test_a_start_design_that_cannot_be_simulated_says_so():
    with pytest.raises(SimulationError, match=r"^Step 0 of the optimisation stopped: .* start design"):
        fj.optimize(_stiff_until(0.4), jnp.full(6, 0.5), fj.MMA(), iterations=2, progress=False)
