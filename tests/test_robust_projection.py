"""The robust formulation of the Heaviside projection (Wang, Lazarov, Sigmund 2011; issue 30): eroded, blueprint
and dilated designs of one filtered field, the objective on the eroded design, the blueprint reported.

The value and gradient checks use a smooth function of the physical densities written in JAX (no simulation);
the continuation run uses top88's half MBB beam (a static compliance solved by SciPy, milliseconds a step), as
tests/test_crisp_designs.py does."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._examples._mbb import MBBBeam

X_MIN = 1e-3
ROBUST = dict(eta_eroded=0.7, eta_dilated=0.3)
# A static compliance is worst on the eroded design (checked in the MBB run below), so its min-max is the objective
# on the eroded design: one SciPy solve per step instead of three.
ROBUST_ERODED = dict(ROBUST, objective="eroded")


def test_eroded_blueprint_dilated_are_ordered_and_the_blueprint_is_the_plain_projection():
    projection = fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST_ERODED)
    plain = fj.HeavisideProjection(0.5, x_min=X_MIN)
    u = jnp.asarray(np.random.default_rng(0).uniform(X_MIN, 1.0, 200))
    for beta in (0.5, 1.0, 8.0, 64.0):
        eroded, blueprint, dilated = projection.designs(u, beta)
        # P_beta at a higher threshold is lower everywhere: tanh(beta (u - eta)) falls with eta, and the
        # normalisation keeps P(0) = 0, P(1) = 1; the ordering is exact up to round-off of the tanh (1e-15).
        assert np.all(np.asarray(eroded) <= np.asarray(blueprint) + 1e-15), f"beta {beta}"
        assert np.all(np.asarray(blueprint) <= np.asarray(dilated) + 1e-15), f"beta {beta}"
        # What the run reports (physical densities, volume, grey share) is the blueprint, bit for bit the plain
        # projection at eta; the objective sees the eroded design.
        np.testing.assert_array_equal(np.asarray(projection(u, beta)), np.asarray(plain(u, beta)))
        np.testing.assert_array_equal(np.asarray(projection.objective_design(u, beta)), np.asarray(eroded))
        np.testing.assert_array_equal(np.asarray(plain.objective_design(u, beta)), np.asarray(plain(u, beta)))
    # At a sharp beta the three differ where they should: u = 0.6 is solid in the blueprint and dilated design,
    # void in the eroded one (at beta = 64, |u - eta| = 0.1 projects to within 0.2 % of 0 or 1).
    eroded, blueprint, dilated = (float(d[0]) for d in projection.designs(jnp.array([0.6]), 64.0))
    assert eroded < 0.01 and blueprint > 0.99 and dilated > 0.99


@pytest.mark.parametrize("thresholds, match", [
    (dict(eta_eroded=0.7), "both thresholds"),
    (dict(eta_dilated=0.3), "both thresholds"),
    (dict(eta_eroded=0.4, eta_dilated=0.3), "0 < eta_dilated < eta < eta_eroded < 1"),
    (dict(eta_eroded=0.7, eta_dilated=0.6), "0 < eta_dilated < eta < eta_eroded < 1"),
    (dict(eta_eroded=1.0, eta_dilated=0.3), "0 < eta_dilated < eta < eta_eroded < 1"),
    (dict(eta_eroded=0.7, eta_dilated=0.0), "0 < eta_dilated < eta < eta_eroded < 1"),
])
def test_bad_thresholds_are_refused_with_the_rule(thresholds, match):
    with pytest.raises(ValueError, match=match):
        fj.HeavisideProjection(0.5, x_min=X_MIN, **thresholds)
    with pytest.raises(ValueError, match="needs the robust formulation"):
        fj.HeavisideProjection(0.5, x_min=X_MIN).designs(jnp.ones(3), 1.0)


def _smooth_objective(x_phys):
    """A smooth stand-in for psi of the physical densities: a stiffness-like term and an inertia-like one."""
    w = jnp.linspace(1.0, 2.0, x_phys.shape[0])
    return jnp.sum(w / (0.05 + x_phys ** 3)) + jnp.sum(w * x_phys) ** 2


@pytest.mark.parametrize("objective", ["eroded", "max"])
def test_robust_objective_value_and_gradient_against_central_differences(objective):
    mbb = MBBBeam(8, 4)
    filt = fj.DensityFilter(mbb.design, 1.5)
    projection = fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST, objective=objective)
    fun = jax.jit(fj.filtered_objective(jax.value_and_grad(_smooth_objective), filt, projection))
    x = jnp.asarray(np.random.default_rng(1).uniform(0.2, 0.9, 32))
    beta = 8.0
    value, grad = fun(x, beta)
    values = np.array([float(_smooth_objective(d)) for d in projection.designs(filt(x), beta)])
    if objective == "eroded":  # the objective of the eroded design of the filtered field
        np.testing.assert_allclose(float(value), values[0], rtol=1e-13)
    else:  # the p-norm (p = 16) of the three: at least the largest, at most 3^(1/16) times it
        np.testing.assert_allclose(float(value), np.sum(values ** 16) ** (1 / 16), rtol=1e-13)
        assert values.max() <= float(value) <= 3 ** (1 / 16) * values.max()
    # Central differences along three directions, step h = 1e-5: the truncation error is h^2 / 6 |f'''| along d;
    # through P_beta (slope up to beta / 2 = 4, its derivatives ~ beta^k) and the cubic terms |f'''| is at most
    # ~1e5 here, so ~2e-6 absolute, and round-off eps |f| / h ~ 1e-16 * 2e2 / 1e-5 = 2e-9: both far below 1e-4
    # of the directional derivatives (order 10-100), which a wrong pullback (the blueprint's or none) misses by
    # tens of per cent.
    h = 1e-5
    for seed in range(3):
        d = jnp.asarray(np.random.default_rng(10 + seed).normal(size=x.shape))
        fd = (fun(x + h * d, beta)[0] - fun(x - h * d, beta)[0]) / (2 * h)
        np.testing.assert_allclose(float(jnp.dot(grad, d)), float(fd), rtol=1e-4, err_msg=f"direction {seed}")


def test_robust_objective_of_a_design_of_several_bodies():
    # A dict design (the two links): each body's filter and the same robust projection; the objective (the
    # default min-max) sees the eroded, blueprint and dilated designs of every body in turn, physical_densities
    # (what a run reports) the blueprint.
    mbb = MBBBeam(8, 4)
    filters = {"coupler": fj.DensityFilter(mbb.design, 1.5), "rocker": fj.DensityFilter(mbb.design, 1.5)}
    projection = fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST)
    seen = []

    def fun(x_phys):
        seen.append(x_phys)
        return sum(jnp.sum(v) for v in x_phys.values()), jax.tree.map(jnp.ones_like, x_phys)

    rng = np.random.default_rng(2)
    x = {"coupler": jnp.asarray(rng.uniform(0.2, 0.9, 32)), "rocker": jnp.asarray(rng.uniform(0.2, 0.9, 32))}
    value, grad = fj.filtered_objective(fun, filters, projection)(x, 8.0)
    assert len(seen) == 3
    for body in x:
        eroded, blueprint, dilated = projection.designs(filters[body](x[body]), 8.0)
        # The same arithmetic under jax.vjp and eagerly: equal to round-off (1e-14 relative), while the eroded
        # and blueprint designs of these densities differ by 0.05-0.5.
        for design, expected in zip(seen, (eroded, blueprint, dilated)):
            np.testing.assert_allclose(np.asarray(design[body]), np.asarray(expected), rtol=1e-13)
        assert np.max(np.abs(np.asarray(blueprint) - np.asarray(eroded))) > 0.05
        np.testing.assert_array_equal(np.asarray(fj.physical_densities(x, filters, projection, 8.0)[body]),
                                      np.asarray(blueprint))
        assert grad[body].shape == x[body].shape


def test_the_robust_options_are_part_of_the_run_fingerprint():
    # A checkpoint of a run with other thresholds or another objective design is refused on resume (fj.optimize
    # compares the objective's and constraints' fingerprints, which cover the projection's static fields).
    from ffr_jax._optimize._fingerprint import tree_fingerprint

    prints = {tree_fingerprint(p) for p in (
        fj.HeavisideProjection(0.5, x_min=X_MIN), fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST),
        fj.HeavisideProjection(0.5, x_min=X_MIN, eta_eroded=0.75, eta_dilated=0.3),
        fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST_ERODED))}
    assert len(prints) == 4
    with pytest.raises(ValueError, match="objective must be one of"):
        fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST, objective="worst")
    with pytest.raises(ValueError, match="needs the robust formulation"):
        fj.HeavisideProjection(0.5, x_min=X_MIN, objective="eroded")


def _topology(design, shape):
    """The numbers of solid and of void pieces (4-connected) of a design thresholded at 0.5."""
    from scipy.ndimage import label

    solid = np.asarray(design).reshape(shape) > 0.5
    return label(solid)[1], label(~solid)[1]


def _mbb_run(mbb, filt, projection, directory):
    """The half MBB beam, filter and projection given, MMA's defaults, volume <= 0.5, beta doubled every 5 steps
    from 1 to 256 (step 40 on), 60 steps, checkpointed at the end."""
    fun = fj.filtered_objective(mbb.value_and_grad, filt, projection)
    volume = fj.VolumeConstraint(0.5, x_min=X_MIN, filter=filt, projection=projection)
    return fj.optimize(fun, np.full(mbb.nelx * mbb.nely, 0.5), fj.MMA(X_MIN), volume, iterations=60, progress=False,
                       beta=fj.beta_continuation(1.0, 256.0, every=5), directory=directory, checkpoint_every=60)


@pytest.fixture(scope="module")
def mbb_robust(tmp_path_factory):
    """36 x 12 elements, filter radius 2.5 elements, the robust formulation with the objective on the eroded design
    (the worst case of a compliance)."""
    mbb = MBBBeam(36, 12)
    filt = fj.DensityFilter(mbb.design, 2.5)
    projection = fj.HeavisideProjection(0.5, x_min=X_MIN, **ROBUST_ERODED)
    directory = tmp_path_factory.mktemp("robust")
    return mbb, filt, projection, _mbb_run(mbb, filt, projection, directory), directory


def test_a_robust_continuation_run_ends_crisp_with_a_minimum_member_size(mbb_robust):
    mbb, filt, projection, result, _ = mbb_robust
    shape = (mbb.nely, mbb.nelx)
    eroded, blueprint, dilated = projection.designs(filt(result.x), 256.0)
    # The run reports the blueprint (its grey share is the recorded one), which ends crisp: below the 5 %
    # (one grey element is 0.23 %).
    assert result.grey == float(fj.grey_share(blueprint)) < 0.05, np.round(result.history.grey, 3)
    assert result.feasible and result.back_offs == 0
    # The premise of evaluating a compliance on the eroded design only: it is the worst of the three (less material,
    # softer), the blueprint next. The gaps are tens of per cent of c (erosion removes a band of the filter's width
    # from every member), far above the SciPy solve's round-off.
    c = [mbb.compliance_and_grad(np.asarray(d))[0] for d in (eroded, blueprint, dilated)]
    assert c[0] > c[1] > c[2], c
    # The minimum length scale: eroding the blueprint (eta 0.7) removes no member and dilating it (eta 0.3) closes
    # no hole; both keep its topology (the numbers of solid and of void pieces).
    topology = _topology(blueprint, shape)
    assert _topology(eroded, shape) == topology == _topology(dilated, shape), "robust: erosion or dilation changed it"


@pytest.mark.slow  # a second run, a few seconds
def test_the_plain_projection_leaves_members_that_erosion_removes(mbb_robust, tmp_path):
    # The plain projection's design at the same settings has members thinner than the robust one's: eroding it at
    # the same threshold breaks or removes some, so the topology check above can fail.
    mbb, filt, projection, _, _ = mbb_robust
    plain = _mbb_run(mbb, filt, fj.HeavisideProjection(0.5, x_min=X_MIN), tmp_path)
    eroded, blueprint, _ = projection.designs(filt(plain.x), 256.0)
    shape = (mbb.nely, mbb.nelx)
    assert _topology(eroded, shape) != _topology(blueprint, shape)


@pytest.mark.slow  # the step compiled again for the resumed run
def test_a_robust_run_resumes_from_its_checkpoint(mbb_robust):
    mbb, filt, projection, result, directory = mbb_robust
    fun = fj.filtered_objective(mbb.value_and_grad, filt, projection)
    volume = fj.VolumeConstraint(0.5, x_min=X_MIN, filter=filt, projection=projection)
    resumed = fj.optimize(fun, np.full(36 * 12, 0.5), fj.MMA(X_MIN), volume, iterations=62, progress=False,
                          beta=fj.beta_continuation(1.0, 256.0, every=5), directory=directory, resume=True)
    assert resumed.history.steps == 62
    np.testing.assert_array_equal(resumed.history.value[:60], result.history.value)
