"""Stress and torque objectives and constraints (issue 31): the qp-relaxed stress modes, the p-norm stress
measure, its design gradient (adjoint = autodiff = central differences), the driving-torque gradient of the
crank-rocker, the peak von Mises stress per element, and bad input.

The default suite runs only the refusals that need no case (its time budget is spent); everything that
builds a case or compiles a simulation is `slow` (CI runs those too)."""

import logging
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._objective._aggregated_stress import aggregated_stress, stress_problem
from ffr_jax._objective._stress_measure import StressMeasure
from ffr_jax._optimize._stress_constraint import stress_constraint
from ffr_jax._outputs._peak_stress import peak_von_mises
from ffr_jax._outputs._relaxed_stresses import relaxed_stress_modes
from ffr_jax._outputs._stresses import stress_modes, von_mises

EPS = np.finfo(float).eps
# Gradient bounds, argued as in tests/test_reactions.py: autodiff is the exact derivative of the discrete
# forward solution (rtol 1e-10), the adjoint that of the continuous one from a backward solve at its
# default rtol 1e-8; they differ by the backward tolerance times a growth of at most 10 (1e-7). Central
# differences with a step 1e-4 along a direction of unit entries: truncation (1e-4)^2 times a third
# derivative of relative order one, plus the forward solves' noise 10 rtol / 1e-4 = 1e-5 at most.
ADJOINT_VS_AUTODIFF = 1e-7
FINITE_DIFFERENCES = 1e-5


@pytest.fixture(scope="module")
def rod():
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    x = case.initial_design(0.5).at[0].set(0.2).at[-1].set(0.9)  # not uniform: the relaxation is seen
    return case, x


@pytest.fixture(scope="module")
def own_limit(rod):
    """The design's own relaxed peak von Mises stress over the motion (21 output times): the stress limit of the
    gradient test, and the normalisation the unreachable-limit test evaluates the solid rod's stress with (the
    limit is an input of the aggregated-stress program: any limit runs the program compiled for the first)."""
    case, x = rod
    traj = fj.simulate(case, x, ts=jnp.linspace(0.0, 0.1, 21))
    return float(jnp.max(peak_von_mises(case, traj, x, relaxation=0.5)))


# --- bad input (no case needed: refused before anything is built or traced) ----------------------------
@pytest.mark.parametrize("limit", [0.0, -1e6, float("nan"), float("inf"), "1e6", True, None])
def test_a_limit_that_is_not_a_positive_number_is_refused(limit):
    with pytest.raises(ValueError, match="stress limit must be a positive finite number"):
        aggregated_stress(None, None, limit)
    with pytest.raises(ValueError, match="stress limit must be a positive finite number"):
        stress_constraint(None, limit)
    with pytest.raises(ValueError, match="stress limit must be a positive finite number"):
        StressMeasure(jnp.zeros((3, 4, 3, 2)), 0, limit)


def test_bad_power_relaxation_modes_and_targets_are_refused():
    with pytest.raises(ValueError, match="power must be a number >= 2"):
        aggregated_stress(None, None, 1e6, power=1.0)
    with pytest.raises(ValueError, match="relaxation exponent"):
        stress_constraint(None, 1e6, relaxation=-0.5)
    with pytest.raises(ValueError, match="takes a case"):
        aggregated_stress("rod", None, 1e6)
    with pytest.raises(ValueError, match="shape \\(n_elements, 4, 3, n_q\\)"):
        StressMeasure(jnp.zeros((3, 4, 2)), 0, 1e6)
    with pytest.raises(ValueError, match="index of the flexible body"):
        StressMeasure(jnp.zeros((3, 4, 3, 2)), -1, 1e6)


# --- the measure ----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_relaxed_stress_modes_are_the_stress_modes_rescaled(rod):
    """`x^s E0 D B phi = x^(s - p) (x^p E0 D B phi)`: the same products up to the rounding of the scalar
    factors (a few eps of each entry; 16 eps of the largest entry leaves room for the sums in D B phi)."""
    case, x = rod
    s, p = 0.5, case.material.stiffness_penalty
    xe = case.design.element_densities(x)
    relaxed = relaxed_stress_modes(case.design, x, s)
    expected = xe[:, None, None, None] ** (s - p) * stress_modes(case.design, x)
    scale = float(jnp.max(jnp.abs(relaxed)))
    assert float(jnp.max(jnp.abs(relaxed - expected))) <= 16 * EPS * scale, "relaxed vs rescaled stress modes"
    same = relaxed_stress_modes(case.design, x, p)  # s = p is the macroscopic stress itself
    assert float(jnp.max(jnp.abs(same - stress_modes(case.design, x)))) <= 16 * EPS * scale


@pytest.mark.slow
def test_stress_measure_is_the_power_sum_of_von_mises(rod):
    """`F = sum (sigma_vm / limit)^P` at a state with random modal coordinates: the squared form of the
    integrand against sqrt-then-power (a few roundings per point, summed over 32 points; 1e-13 relative)."""
    case, x = rod
    modes = relaxed_stress_modes(case.design, x, 0.5)
    scene = case.problem_for(x).scene
    y_r = jax.random.normal(jax.random.PRNGKey(0), (scene.n_coordinates,))
    vm = von_mises(jnp.einsum("egck,k->egc", modes, y_r[3:]))
    limit = float(jnp.max(vm))
    measure = StressMeasure(modes, 0, limit, 8)
    expected = jnp.sum((vm / limit) ** 8)
    np.testing.assert_allclose(measure(0.0, y_r, jnp.zeros_like(y_r), scene), expected, rtol=1e-13)
    assert float(expected) >= 1.0  # the largest point alone contributes 1: the sum bounds the peak from above
    with pytest.raises(ValueError, match="does not have the 2 shape vectors"):
        StressMeasure(modes, 1, limit)(0.0, y_r, jnp.zeros_like(y_r), scene)


@pytest.mark.slow
def test_peak_von_mises_per_element(rod):
    """The peak over the output times of the macroscopic stress is the maximum of fj.stresses' von Mises;
    the relaxed peak is it times x_e^(s - p) element by element (same products: 1e-12)."""
    case, x = rod
    traj = fj.simulate(case, x, ts=jnp.linspace(0.0, 0.1, 5))
    peak = peak_von_mises(case, traj, x)
    assert peak.shape == (case.mesh.n_elements,)
    np.testing.assert_allclose(peak, jnp.max(von_mises(fj.stresses(case, traj, x)), axis=(0, 2)), rtol=1e-12)
    relaxed = peak_von_mises(case, traj, x, relaxation=0.5)
    xe = np.asarray(case.design.element_densities(x))
    np.testing.assert_allclose(relaxed, peak * xe ** (0.5 - case.material.stiffness_penalty), rtol=1e-12)
    with pytest.raises(ValueError, match="Trajectory"):
        peak_von_mises(case, traj.positions, x)


@pytest.mark.slow
def test_a_joint_not_in_the_scene_is_refused(rod):
    case, _ = rod
    with pytest.raises(ValueError, match="No joint 'AngleDriver\\(crank\\)'.*CrankPin\\(rod\\)"):
        fj.JointLoad(case, "AngleDriver(crank)")
    with pytest.raises(ValueError, match="No joint 7"):
        fj.JointLoad(case, 7)


# --- gradients ------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_stress_measure_gradient_adjoint_autodiff_fd(rod, own_limit, caplog):
    """d sigma_PN / dx of the relaxed 8-norm stress by the adjoint, by autodiff and, along one direction, by
    central differences of psi. The limit is the design's own relaxed peak, so psi / T is of order one and
    the adjoint's absolute tolerances (1e-10 on adjoint variables of the size of psi) are not the limit.
    (91 s on two loaded cores.)"""
    case, x = rod
    limit = own_limit
    (s_adj, adjoint), (s_ad, autodiff) = (aggregated_stress(case, x, limit, method=m) for m in ("adjoint", "autodiff"))
    adjoint, autodiff = np.asarray(adjoint), np.asarray(autodiff)
    np.testing.assert_allclose(s_adj, s_ad, rtol=1e-9)  # the same forward solve's psi at rtol 1e-10
    np.testing.assert_allclose(adjoint, autodiff, rtol=ADJOINT_VS_AUTODIFF, atol=ADJOINT_VS_AUTODIFF *
                               np.max(np.abs(autodiff)), err_msg="stress measure: adjoint vs autodiff")
    # Another limit is an input of the same compiled program: nothing compiles again (until 27 Nov the limit was a
    # static value, and each new limit compiled the program again, ~12 s). sigma_PN does not depend on the limit it
    # is normalised by (psi scales as limit^-P): equal to the solves' accuracy, psi's relative error 10 rtol plus
    # atol / psi (1e-9 + 1e-12 / 4e-4 at twice the limit), divided by P in sigma_PN: 1e-8 is a bound with room.
    with caplog.at_level(logging.INFO, logger="ffr_jax"):
        s_twice, _ = aggregated_stress(case, x, 2.0 * limit, method="adjoint")
    compiled = [r.getMessage() for r in caplog.records if r.getMessage().startswith("compiling")]
    assert not compiled, f"a new stress limit compiled again: {compiled}"
    np.testing.assert_allclose(s_twice, s_adj, rtol=1e-8)
    v, h, power = np.linspace(1.0, -1.0, x.size), 1e-4, 8.0
    psi = [float(fj.objective(stress_problem(case, x + d * h * v, limit, power, 0.5))) for d in (1, -1)]
    sigma = [limit * (p / case.t1) ** (1 / power) for p in psi]
    fd = (sigma[0] - sigma[1]) / (2 * h)
    assert abs(fd - autodiff @ v) <= FINITE_DIFFERENCES * np.abs(autodiff) @ np.abs(v), \
        f"stress measure: central differences {fd:.10e} vs autodiff {autodiff @ v:.10e}"


@pytest.mark.slow
def test_angle_driver_torque_gradient_adjoint_fd():
    """`int tau^2 dt` of the crank's angle driver on the crank-rocker with the family coupler: d psi / dx by
    the adjoint against central differences of `fj.objective` along two directions (bounds above: the
    difference's error plus the adjoint's). Adjoint = autodiff for a `JointLoad` torque is
    tests/test_reactions.py::test_driving_torque_design_gradient_adjoint_autodiff_fd (the crank pin of the
    slider-crank) and for a joint force its test_joint_load_gradient_adjoint_autodiff_fd: the autodiff
    program of this four-bar (its compile ~100 s of CPU, the heaviest part of this test in CI's slow set)
    is not compiled again here.

    The central differences take psi from the adjoint program compiled for the gradient (its forward solve: Dopri8
    at rtol 1e-10 / atol 1e-12, `fj.objective`'s defaults too, so the same psi up to round-off and the bound above
    holds unchanged), not from a forward program of its own: one compile of the four-bar less, four backward solves
    more (78 s -> 67 s on one quiet core)."""
    case = fj.cases.four_bar(4, 2, 2, 0.1)
    case = case.with_objective(fj.JointLoad(case, "AngleDriver(crank)", "torque", 2))
    x = jnp.asarray(np.asarray(case.initial_design(0.5).at[0].set(0.3)))  # strongly typed, as x +- h v: one program

    def objective(y):  # psi of the adjoint program of the gradient below (same call, same program)
        return float(fj.value_and_grad(case, y, method="adjoint")[0])

    adjoint = np.asarray(fj.value_and_grad(case, x, method="adjoint")[1])

    h = 1e-4
    for v in (np.linspace(1.0, -1.0, x.size), np.random.default_rng(0).choice([-1.0, 1.0], x.size)):
        fd = (objective(x + h * v) - objective(x - h * v)) / (2 * h)
        bound = (FINITE_DIFFERENCES + ADJOINT_VS_AUTODIFF) * np.abs(adjoint) @ np.abs(v)
        assert abs(fd - adjoint @ v) <= bound, f"driving torque: central differences {fd:.10e} vs adjoint {adjoint @ v:.10e}"


# --- a limit no design meets ----------------------------------------------------------------------------
@pytest.mark.slow
def test_an_unreachable_stress_limit_is_reported_by_the_optimizer(rod, own_limit):
    """A limit 1000x below the relaxed 8-norm stress of the solid rod: for a uniform design the relaxed stress
    scales as x^(s + 1 - p) (K ~ x^p, inertia loads ~ x), smallest at x = 1, and two MMA steps of move 0.2
    cannot lower it 1000-fold; the run must end with the stress constraint named as violated.
    sigma_PN does not depend on the normalising limit (it is factored out again); the solid rod's is evaluated
    with the gradient test's limit, so with the adjoint program compiled there (it was 1e3 Pa: 12 s of compile)."""
    case, x = rod
    solid = case.initial_design(1.0)
    sigma_solid, _ = aggregated_stress(case, solid, own_limit)
    constraint = stress_constraint(case, 1e-3 * float(sigma_solid))
    with pytest.warns(fj.ConstraintViolationWarning, match="stress"):
        result = fj.optimize(fj.make_objective(case), x, fj.MMA(), [constraint], iterations=2, progress=False)
    assert not result.feasible and result.constraints[0] > 100.0


# --- output: the VTU series and the picture --------------------------------------------------------------
@pytest.mark.slow
def test_vtu_series_carries_the_von_mises_stress(rod, tmp_path):
    """Each frame's `von_mises` cell data is the element von Mises stress of that frame's modal coordinates
    (the same program: 1e-12), `peak_von_mises` its maximum over the frames."""
    import meshio

    from ffr_jax._app._animation import body_motion
    from ffr_jax._outputs._peak_stress import element_von_mises

    case, x = rod
    pvd = fj.write_vtu_series(tmp_path / "motion.pvd", case, x, frames=3)
    frames = [meshio.read(f) for f in sorted((tmp_path / "motion_vtu").glob("*.vtu"))]
    _, _, y_r = body_motion(case, x, np.linspace(case.t0, case.t1, 3))  # the motion the series draws
    expected = np.asarray(element_von_mises(case.design, x, jnp.asarray(y_r[:, 3:])))
    scale = expected.max()
    for k, frame in enumerate(frames):
        np.testing.assert_allclose(frame.cell_data["von_mises"][0], expected[k], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(frame.cell_data["peak_von_mises"][0], expected.max(axis=0), rtol=0,
                                   atol=1e-12 * scale)
    assert pvd.exists() and scale > 0


@pytest.mark.slow
def test_plot_peak_stress(rod):
    from ffr_jax._app._stress_plot import plot_peak_stress

    case, _ = rod
    peak = np.linspace(0.0, 2e6, case.mesh.n_elements)
    ax = plot_peak_stress(case, peak, limit=1e6, title="peak")
    assert len(ax.collections) == 2  # the field and the outlines of the elements over the limit
    with pytest.raises(ValueError, match="one value per element"):
        plot_peak_stress(case, peak[:-1])
