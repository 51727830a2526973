"""Objectives of the motion as constraints, and several operating conditions as one batched solve.

- A kinetic-energy bound (an [`Objective`][] of the problem issue) through [`FunctionConstraint`][]
  with its adjoint gradient in an MMA run: the bound ends active and held, its logged value is
  that of an independent forward simulation.
- Two crank speeds of the slider–crank as [`OperatingConditions`][]: the batched (`vmap`) adjoint
  value and gradient equal the two separate solves (central differences), weighted and worst case
  (one compiled program for both).
"""

import equinox as eqx
import jax
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._app._cli_io import slider_crank_case

from helpers import random_design

RTOL, ATOL = 1e-8, 1e-12
SLOW = 8 * np.pi  # the second crank speed (the reference runs up to 12 pi)


@pytest.fixture(scope="module")
def case():
    # The tiny case of the CLI tests (test_io.py, test_optimize.py): the same object, so compiled
    # programs that take it (the modal analysis) are shared.
    return slider_crank_case(8, 2, 2, 0.2)


@pytest.fixture(scope="module")
def slow(case):
    return fj.cases.slider_crank(8, 2, 2, 0.2, speed=SLOW)


# --- an objective of the motion as a constraint -----------------------------------------------------
def test_mma_holds_a_kinetic_energy_bound_with_its_adjoint_gradient(case, tmp_path):
    # int T dt of the rod (KineticEnergy of the problem issue) through FunctionConstraint, its gradient
    # by the adjoint (checked against autodiff and finite differences in test_problem.py) and the
    # filter's transpose. The objective pulls the other way: the heaviest rod (T is nearly linear in
    # the mass, the rod moving almost rigidly), so the bound, 90 % of the uniform x = 0.5 rod's,
    # must end active and held.
    energy_case = case.with_objective(fj.KineticEnergy())
    filt = fj.DensityFilter(case.design, 1.5)
    forward = jax.jit(lambda x_phys: fj.objective(energy_case, x_phys, rtol=1e-10, atol=1e-12))
    energy0 = float(forward(filt(case.initial_design(0.5))))
    energy = fj.FunctionConstraint(fj.make_objective(energy_case, "adjoint", filter=filt, rtol=RTOL, atol=ATOL),
                                   0.9 * energy0, name="kinetic_energy")
    mass = fj.MassConstraint(case.design, 1e6, filter=filt)  # only its mass and gradient: m = 1e6 (g + 1)
    scale = 1e6 / mass.range[1]

    def heaviest(x):  # minimise -m(H x) / m_solid
        g, grad = mass.value_and_grad(x)
        return -(g + 1.0) * scale, -grad * scale

    volume = fj.VolumeConstraint(0.5, x_min=case.material.x_min, filter=filt)  # for MMA: mean(c x) <= V
    result = fj.optimize(heaviest, case.initial_design(0.5), fj.MMA(case.material.x_min, move=0.2),
                         (volume, energy), iterations=10, directory=tmp_path, checkpoint_every=5, progress=False)
    history = result.history
    assert history.names == ("volume", "kinetic_energy")
    assert history.constraint_values[0, 1] > 0.09, "the start design lies 11 % above the bound"
    assert result.feasible, result.descriptions
    # The final constraint value against an independent forward simulation of the design at rtol
    # 1e-10: the loop's rtol 1e-8 makes T accurate to ~1e-8 relative, so 1e-6 leaves room and still
    # catches a mismatch of design and value (a stale design moves T by percents per MMA step).
    energy_end = float(forward(filt(result.x)))
    np.testing.assert_allclose(result.constraints[1], energy_end / energy.bound - 1.0, atol=1e-6)
    # Active: the run ends near the bound (within 1 %), not far inside it, because mass is rewarded.
    assert -1e-2 < energy_end / energy.bound - 1.0 <= 1e-3, result.descriptions
    assert "kinetic_energy" in result.descriptions[1] and "holds" in result.descriptions[1]
    log = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(log[:, 5], history.constraint_values[:, 1], err_msg="the g column of the log")


# --- several operating conditions -----------------------------------------------------------------
@pytest.fixture(scope="module")
def separate(case, slow):
    """psi and its gradient of each speed by its own solves: central differences (an independent route)."""
    x = random_design(case, 5)
    fd = fj.FiniteDifferences(step=1e-4)
    return x, [fj.value_and_grad(c, x, fd, rtol=1e-12, atol=1e-14) for c in (case, slow)]


@eqx.filter_jit
def batched(conditions, x):  # one program for both combinations (the choice is an array of the conditions)
    return conditions.value_and_grad(x, "adjoint", rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("combine", ["weighted", "worst"])
def test_two_crank_speeds_as_one_batched_solve(case, slow, separate, combine):
    x, ((psi_fast, grad_fast), (psi_slow, grad_slow)) = separate
    conditions = fj.OperatingConditions([case, slow], weights=[0.25, 0.75], combine=combine)
    value, grad, psis = batched(conditions, x)
    assert psi_fast > 1.5 * psi_slow, "the faster crank loads the rod more: the conditions differ"
    # psi_k at rtol 1e-10 against the separate solves at 1e-12: ~1e-10 relative. The gradient against
    # central differences (h = 1e-4): truncation h^2 |psi'''| / 6 and forward noise 1e-12 / h are
    # both ~1e-8 of max|grad|, the adjoint's error ~1e-9. 1e-5 is far above these and far below what
    # a batching error gives (conditions swapped or a gradient summed twice: factors of 2 and more).
    np.testing.assert_allclose(psis, [psi_fast, psi_slow], rtol=1e-8)
    weighted = combine == "weighted"
    np.testing.assert_allclose(value, 0.25 * psi_fast + 0.75 * psi_slow if weighted else psi_fast, rtol=1e-8)
    expected = 0.25 * grad_fast + 0.75 * grad_slow if weighted else grad_fast
    np.testing.assert_allclose(grad, expected, rtol=0, atol=1e-5 * np.abs(expected).max())
    assert conditions.combine == combine


def test_operating_conditions_refuse_conditions_of_another_structure(case, slow):
    with pytest.raises(ValueError, match="structure"):
        fj.OperatingConditions([case, fj.cases.slider_crank(8, 2, 2, 0.3)])  # another t1
    with pytest.raises(ValueError, match="designs other bodies"):
        fj.OperatingConditions([case, fj.cases.slider_crank(10, 2, 2, 0.2)])  # another mesh
    with pytest.raises(ValueError, match="weights"):
        fj.OperatingConditions([case, slow], weights=[1.0, -1.0])
    with pytest.raises(ValueError, match="combine"):
        fj.OperatingConditions([case, slow], combine="mean")
    with pytest.raises(ValueError, match="two or more"):
        fj.OperatingConditions([case])
