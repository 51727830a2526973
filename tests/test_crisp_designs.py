"""Crisp designs (issue 30): the grey share of a design, and the default projection continuation of
`fj.optimize` with MMA ending in a 0/1 design.

The continuation runs on top88's half MBB beam (a static compliance solved by SciPy: a step costs
milliseconds, so a whole continuation to beta = 32 fits the default suite) and, under `-m slow`, on a small
member of the slider–crank family."""

import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._examples._mbb import MBBBeam
from ffr_jax._optimize._mma import projected_move
from helpers import small_case

VOLUME = 0.5
# The acceptance bound for "a short continuation run ends crisp": below 5 % of the elements grey.
CRISP = 0.05


def test_grey_share_counts_the_elements_strictly_inside_the_band():
    x = jnp.array([0.001, 0.1, 0.1000001, 0.5, 0.8999999, 0.9, 1.0, 0.95])
    assert float(fj.grey_share(x)) == 3 / 8, "0.1 and 0.9 themselves are not grey"
    assert float(fj.grey_share(jnp.array([0.001, 1.0, 1.0]))) == 0.0, "a 0/1 design"
    assert float(fj.grey_share(jnp.full(5, VOLUME))) == 1.0, "the uniform start design"
    # The area share: the grey element carries 3 of 3 + 1 + 1 units of area.
    assert float(fj.grey_share(jnp.array([0.5, 1.0, 0.01]), areas=jnp.array([3.0, 1.0, 1.0]))) == 0.6
    # A design of several bodies: the share over all their elements together.
    assert float(fj.grey_share({"coupler": jnp.array([0.5, 1.0]), "rocker": jnp.array([0.01, 0.01])})) == 0.25
    assert float(fj.grey_share(x, low=0.0, high=1.0)) == 7 / 8, "a band of one's own"
    with pytest.raises(ValueError, match="low < high"):
        fj.grey_share(x, low=0.9, high=0.1)
    with pytest.raises(ValueError, match="one area per design element"):
        fj.grey_share(x, areas=jnp.ones(3))


def test_projected_move_limit_bounds_the_physical_change():
    # The largest slope of P_beta at eta = 0.5 is beta / (2 tanh(beta / 2)) (1.0820 at beta = 1, 16 at beta = 32
    # to 1e-13); the physical change s * m must stay within 2 * move, and at beta -> 0 (slope 1) nothing is cut.
    move = 0.2
    for beta in (1e-3, 1.0, 4.0, 32.0):
        m = float(projected_move(move, jnp.asarray(beta)))
        slope = beta / (2.0 * np.tanh(beta / 2.0))
        assert m <= move and slope * m <= 2.0 * move * (1.0 + 1e-15), f"beta {beta}: move {m}"
    assert float(projected_move(move, jnp.asarray(1.0))) == move
    np.testing.assert_allclose(float(projected_move(move, jnp.asarray(32.0))), 2.0 * move / 16.0, rtol=1e-12)


@pytest.fixture(scope="module")
def mbb_run(tmp_path_factory):
    """The half MBB beam, 24 x 8, filter 1.5 elements, projection, MMA's defaults, and no `beta`: fj.optimize
    takes its default continuation (1, 2, ..., 32 doubled every 10 steps); 5 steps at beta = 32."""
    mbb = MBBBeam(24, 8)
    filt = fj.DensityFilter(mbb.design, 1.5)
    projection = fj.HeavisideProjection(0.5, x_min=1e-3)
    fun = fj.filtered_objective(mbb.value_and_grad, filt, projection)
    volume = fj.VolumeConstraint(VOLUME, x_min=1e-3, filter=filt, projection=projection)
    x0 = np.full(mbb.nelx * mbb.nely, VOLUME)
    directory = tmp_path_factory.mktemp("mbb")
    result = fj.optimize(fun, x0, fj.MMA(1e-3), volume, iterations=55, progress=False, directory=directory,
                         checkpoint_every=55)
    return mbb, filt, projection, result, directory


def test_a_short_continuation_run_ends_crisp(mbb_run):
    mbb, filt, projection, result, _ = mbb_run
    history = result.history
    schedule = fj.beta_continuation()
    # The default schedule reached its cap, and the recorded share is that of the final design's physical
    # densities at the last step's beta (the same map the run's volume constraint holds).
    assert schedule(history.steps - 1) == 32.0
    x_phys = fj.physical_densities(result.x, filt, projection, beta=32.0)
    assert result.grey == history.grey[-1] == float(fj.grey_share(x_phys))
    assert history.grey[0] > 0.5, "the first steps are grey (beta = 1): the measure is not trivially 0"
    assert result.grey < CRISP, f"grey share per step: {np.round(history.grey, 3)}"
    # The volume bound holds to MMA's subproblem tolerance (epsimin 1e-7 on the normalised constraint) at the
    # end; no update was redone; the design is far stiffer than the uniform one (a 0/1 beam against
    # x = 0.5 everywhere, whose stiffness is 0.5^3 of the solid's: its compliance is > 3x a good layout's).
    assert result.feasible and result.constraints[0] <= 1e-6 and result.back_offs == 0
    uniform = mbb.compliance_and_grad(np.full(x_phys.shape, VOLUME))[0]
    assert history.value[-1] < uniform / 3, (history.value[-1], uniform)


def test_continuation_run_records_the_grey_share_in_the_checkpoint(mbb_run):
    # The share is kept with the history in the checkpoint, so a resumed run's history is the whole run's.
    *_, result, directory = mbb_run
    stored = fj.load_checkpoint(directory / "checkpoint.npz").history
    np.testing.assert_array_equal(stored.grey, result.history.grey)
    assert stored.grey.shape == (55,) and np.all((stored.grey >= 0) & (stored.grey <= 1))


@pytest.mark.slow
def test_a_short_continuation_run_on_the_slider_crank_ends_crisp():
    # slider_crank(8, 4, 2, 0.1): 6 x 4 = 24 design elements (the end columns hold the joints), MMA's default
    # move, beta doubled every 3 steps to 32 at step 15, three steps there. psi falls to about 0.2 of the start's
    # (measured with a doubling every 4 steps: 0.20 from step 12 on); one grey element is 4.2 %, so crisp means
    # at most one.
    case = small_case(8, 4, 2, 0.1)
    filt = fj.DensityFilter(case.design, radius=1.5)
    projection = fj.HeavisideProjection(0.5, x_min=case.material.x_min)
    fun = fj.make_objective(case, "adjoint", filter=filt, projection=projection, rtol=1e-6, atol=1e-12)
    volume = fj.VolumeConstraint(VOLUME, x_min=case.material.x_min, filter=filt, projection=projection)
    result = fj.optimize(fun, case.initial_design(VOLUME), fj.MMA(case.material.x_min), volume, iterations=18,
                         progress=False, beta=fj.beta_continuation(1.0, 32.0, every=3))
    psi = result.history.value
    assert result.grey < CRISP, f"grey share per step: {np.round(result.history.grey, 3)}"
    # psi falls by half at least (a 0/1 rod against the uniform one; the bound is far above the solves' rtol),
    # the volume holds (MMA's subproblem tolerance, see above) and no update was redone.
    assert psi[-1] < 0.5 * psi[0], psi / psi[0]
    assert result.feasible and result.constraints[0] <= 1e-6 and result.back_offs == 0


@pytest.mark.slow
def test_cli_mma_projects_by_default_and_reports_the_grey_share(tmp_path, capsys):
    from ffr_jax._app._cli import main

    # test_optimize.py's tiny CLI case and tolerances (its compiled objective), with MMA and no projection option.
    assert main(["optimize", "slider-crank", "--nx", "8", "--ny", "2", "--modes", "2", "--t1", "0.2", "--rtol", "1e-6",
                 "--atol", "1e-12", "--method", "adjoint", "--optimizer", "mma", "--iters", "2", "--no-progress",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Heaviside projection beta 1.0 -> 32.0 (x2 every 10)" in out, out
    saved = np.load(tmp_path / "design.npz")
    grey = float(fj.grey_share(saved["x_phys"]))
    assert float(saved["grey"]) == grey == saved["grey_history"][-1]
    assert f"grey share of the final design (0.1 < x_phys < 0.9): {100 * grey:.1f} % at beta 1" in out, out


@pytest.mark.slow  # the case build (a few seconds) would cost the default suite's budget
def test_cli_filter_length_is_a_radius_in_metres(tmp_path, capsys):
    from ffr_jax._app._cli import main
    from ffr_jax._app._cli_optimize import _problem

    # The CLI's filter of --filter-length r: the radius measured in the mesh's length unit, scale (1, 1), equal to
    # fj.DensityFilter(.., r, scale=(1, 1)). On the 8 x 2 rod (elements 0.125 m x 0.03 m) r = 0.05 m reaches the
    # neighbours across the rod only, unlike the default 1.5 element sizes (the 8 nearest).
    geometry = (("modes", 2), ("nx", 8), ("ny", 2), ("t1", 0.2))
    case, filt, _, _ = _problem("slider-crank", geometry, 1.5, None, "adjoint", 1e-6, 1e-12, 0.05)
    expected = fj.DensityFilter(case.design, 0.05, scale=(1.0, 1.0))
    np.testing.assert_array_equal(np.asarray(filt.weights), np.asarray(expected.weights))
    np.testing.assert_array_equal(np.asarray(filt.neighbours), np.asarray(expected.neighbours))
    in_elements = fj.DensityFilter(case.design, 1.5)
    assert filt.weights.shape != in_elements.weights.shape or not np.array_equal(filt.weights, in_elements.weights)
    # A negative length is refused at the door, before anything compiles.
    assert main(["optimize", "slider-crank", "--nx", "8", "--ny", "2", "--filter-length", "-1",
                 "--out", str(tmp_path / "bad")]) == 2
    assert "--filter-length must lie in" in capsys.readouterr().err
