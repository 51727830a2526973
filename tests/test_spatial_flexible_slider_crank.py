"""The paper's slider–crank embedded in space (issue 26, Must show): `fj.cases.slider_crank(..., spatial=True)` is
built from spatial bodies and joints (a rigid spatial crank on a ground hinge about `z` with the driven angle, the
rod's design lifted to 3D and hinged to the crank pin, the slider point on the plane `y = 0`), and gives the planar
case's `psi` and design gradient; its gradients by the adjoint agree with automatic differentiation and with central
differences for body-data parameters and the design densities.

Both cases integrate the same ODE in the same independent coordinates (the rod's `q`): the spatial equations reduce
to the planar ones exactly (tests/test_spatial_flexible_lift.py), so the two right-hand sides differ by round-off
only, and the two solutions by the solver's error propagation of that round-off. Tolerances:
- `psi`: 1e-8 relative (issue 26). Each `psi` is accurate to about rtol = 1e-10 times the error growth of the
  0.1 s motion (< 100): two such solutions differ by at most ~1e-8 of `psi`, and by round-off when the step
  sequences coincide.
- gradient: 1e-6 of the largest entry (issue 26): the adjoint integrates backward at rtol 1e-10 as well, and its
  gradient carries the same relative error, ~1e-8, amplified by the adjoint's error growth.
Slow: compiling the spatial problem's programs takes minutes on the shared 2-core machine (benchmarks/RESULTS.md,
"Spatial slider–crank"); the planar ones tens of seconds. So the module compiles three programs and shares them:
the planar case's adjoint design gradient (its `psi` is the planar reference of both comparisons), and for the spatial
problem at the design, `problem = case.problem_for(x)`, its adjoint gradient (whose `psi` serves every central
difference, densities and body data alike) and its forward-mode derivative (`jax.jacfwd` through the solver). The spatial design gradient is the adjoint's scene
gradient pulled back through `p(x)` by one VJP: the composition `fj.value_and_grad(case, x)` performs
(`AbstractSensitivity.value_and_grad_design`), here without compiling it as a fifth program.
"""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj

RTOL, ATOL = 1e-10, 1e-12
PSI_RTOL = 1e-8
GRAD_RTOL = 1e-6
# Adjoint vs autodiff: two discretisations of the same derivative, each accurate to about the solver tolerance
# (1e-10) times the conditioning of the motion; 1e-6 of the largest entry leaves a wide margin and still catches a
# missing term (a wrong sign of a gyroscopic term changes entries at the percent level).
ADJOINT_VS_AUTODIFF = 1e-6
# Central differences with relative step h = 1e-4: truncation ~ h^2 ~ 1e-8 relative, solver noise
# ~ rtol |psi| / (h |dpsi|) ~ 1e-10 / 1e-4 = 1e-6 relative; 1e-5 of the derivative's scale bounds both.
FD_STEP, FD_RTOL = 1e-4, 1e-5


def _design(case):
    """A non-uniform design (a uniform one hides errors that only move the mass around)."""
    return case.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(case.n_design, dtype=float))


@pytest.fixture(scope="module")
def cases():
    planar = fj.cases.slider_crank(4, 2, 2, 0.1)
    spatial = fj.cases.slider_crank(4, 2, 2, 0.1, spatial=True)
    return planar, spatial, _design(planar)


@pytest.fixture(scope="module")
def planar_gradient(cases):
    planar, _, x = cases
    return fj.value_and_grad(planar, x, method="adjoint", rtol=RTOL, atol=ATOL)


@pytest.fixture(scope="module")
def spatial_problem(cases):
    """The spatial problem at the design and the pullback of `p(x)` (`Case.scene`) for its design gradient."""
    _, spatial, x = cases
    scene, pullback = eqx.filter_vjp(spatial.scene, x)
    return spatial.problem.with_scene(scene), pullback


def _objective(problem):
    """`psi` of a spatial problem, from the adjoint program `scene_gradient` compiled (its forward solve, the same
    tolerances): every central difference runs that one program instead of a forward program of its own (one
    spatial compile less; the ten backward solves cost seconds)."""
    return fj.value_and_grad(problem, method="adjoint", rtol=RTOL, atol=ATOL)[0]


@pytest.fixture(scope="module")
def scene_gradient(spatial_problem):
    problem, _ = spatial_problem
    return problem, fj.value_and_grad(problem, method="adjoint", rtol=RTOL, atol=ATOL)


@pytest.fixture(scope="module")
def spatial_design_gradient(spatial_problem, scene_gradient):
    _, pullback = spatial_problem
    _, (psi, grad) = scene_gradient
    (g_x,) = pullback(grad.scene)
    return psi, g_x


def test_bad_input_at_the_door():
    """Spatial joints with a zero-length axis, normal or direction. (A non-boolean `spatial` is a ValueError at
    the door too; under the suite's type checking the annotation refuses it first.)"""
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialPointOnPlane(0, 1, normal=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialPointOnLine(0, 1, direction=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="zero length"):
        fj.SpatialRevolute(0, 0, (0.0, 0.0, 1.0), body_j=1, marker_j=1, axis_j=(0.0, 0.0, 0.0))


@pytest.mark.slow
def test_spatial_case_is_built_from_spatial_parts(cases):
    """Spatial bodies and joints; the rod's independent coordinates are its modal coordinates, as in the plane."""
    _, spatial, _ = cases
    scene = spatial.problem.scene
    assert isinstance(scene.bodies[0].data, fj.SpatialFlexibleBodyData)
    assert isinstance(scene.bodies[1].data, fj.SpatialBodyData)
    assert {type(c).__name__ for c in scene.constraints} == {"SpatialRevolute", "SpatialAngleDriver",
                                                             "EulerNormalisation", "SpatialPointOnPlane"}
    names = scene.coordinate_names()
    assert [names[i] for i in spatial.problem.model.partition.independent] == ["rod.q_1", "rod.q_2"]


@pytest.mark.slow
def test_objective_equals_planar(spatial_problem, planar_gradient):
    psi_p, psi_s = planar_gradient[0], _objective(spatial_problem[0])
    assert abs(float(psi_s - psi_p)) <= PSI_RTOL * abs(float(psi_p)), f"psi: spatial {psi_s}, planar {psi_p}"


@pytest.mark.slow
def test_value_and_grad_equals_planar(planar_gradient, spatial_design_gradient):
    (psi_p, g_p), (psi_s, g_s) = planar_gradient, spatial_design_gradient
    assert abs(float(psi_s - psi_p)) <= PSI_RTOL * abs(float(psi_p)), f"psi: spatial {psi_s}, planar {psi_p}"
    diff = float(jnp.max(jnp.abs(g_s - g_p)))
    assert diff <= GRAD_RTOL * float(jnp.max(jnp.abs(g_p))), f"gradient differs by {diff} (max norm)"


@pytest.mark.slow
def test_design_gradient_matches_central_differences(cases, spatial_design_gradient):
    """Along a random direction `d` of the densities: `grad . d` = `(psi(x + h d) - psi(x - h d)) / 2h`."""
    _, spatial, x = cases
    _, grad = spatial_design_gradient
    d = jnp.asarray(np.random.default_rng(5).uniform(-1.0, 1.0, spatial.n_design))
    h = FD_STEP
    fd = float(_objective(spatial.problem_for(x + h * d)) - _objective(spatial.problem_for(x - h * d))) / (2 * h)
    got = float(grad @ d)
    assert abs(got - fd) <= FD_RTOL * float(jnp.sum(jnp.abs(grad))), f"adjoint {got}, central differences {fd}"


# Body-data parameters of the lifted rod: (name, selector, entries perturbed together).
DIRECTIONS = (
    ("K_qq[0, 0]", lambda p: p.scene.bodies[0].data.modal_stiffness, ((0, 0),)),
    ("C0_yy (in-plane second moment)", lambda p: p.scene.bodies[0].data.second_moment, ((1, 1),)),
    ("S1_y[1]", lambda p: p.scene.bodies[0].data.modal_moment, ((1, 1),)),
    ("C1[0]_xy", lambda p: p.scene.bodies[0].data.second_moment_q, ((0, 0, 1),)),
)


def _perturbed(problem, select, entries, delta):
    a = select(problem)
    for e in entries:
        a = a.at[e].add(delta)
    return eqx.tree_at(select, problem, a)


@pytest.mark.slow
def test_body_data_gradient_matches_central_differences(scene_gradient):
    problem, (_, grad) = scene_gradient
    derivatives = {name: sum(float(select(grad)[e]) for e in entries) for name, select, entries in DIRECTIONS}
    scale = max(abs(v) for v in derivatives.values())
    for name, select, entries in DIRECTIONS:
        h = FD_STEP * max(abs(sum(float(select(problem)[e]) for e in entries)), 1e-3)
        fd = float(_objective(_perturbed(problem, select, entries, h))
                   - _objective(_perturbed(problem, select, entries, -h))) / (2 * h)
        assert abs(derivatives[name] - fd) <= FD_RTOL * scale, \
            f"d psi / d {name}: adjoint {derivatives[name]}, central differences {fd}"


@pytest.mark.slow
def test_adjoint_matches_autodiff(scene_gradient):
    """The adjoint's gradient equals automatic differentiation through the solver on every array of the spatial scene
    (body data of rod and crank, joints, driver law): forward mode (`jax.jacfwd` over the scene's 173 float entries,
    diffrax's `ForwardMode`), the exact derivative of the discrete forward solution, as `jax.grad` through the solver
    (`method="autodiff"`) is: the same derivative, by the same tolerance argument (ADJOINT_VS_AUTODIFF). Forward mode
    compiles and runs in 62-66 s here where the reverse-mode autodiff program took 116 s (one core, quiet machine); the
    public `method="autodiff"` on a spatial problem is tests/test_spatial_gradient.py's.

    Not on the initial state `y0, z0`: there the two differ by 6e-4 of the largest entry (d psi / d q_2(0): adjoint
    -8.996e-7, autodiff -8.642e-7, central differences -8.953e-7), identically for the planar case (measured on
    `slider_crank(4, 2, 2, 0.1)` at this design), so it is a property of the sensitivity methods for initial
    values, not of the spatial equations: only the adjoint converges to central differences there as its backward
    tolerance tightens (4.3e-6 at 1e-12), autodiff and the discrete adjoint differentiate on the forward steps
    (benchmarks/RESULTS.md, "Gradients with respect to the initial state")."""
    problem, (psi, grad) = scene_gradient
    dynamic, static = eqx.partition(problem.scene, eqx.is_inexact_array)
    entries, unravel = jax.flatten_util.ravel_pytree(dynamic)

    def psi_of(p):
        value = fj.simulate(problem.with_scene(eqx.combine(unravel(p), static)), rtol=RTOL, atol=ATOL,
                            adjoint=diffrax.ForwardMode()).psi
        return value, value

    flat_ad, psi_ad = jax.jit(jax.jacfwd(psi_of, has_aux=True))(entries)
    np.testing.assert_allclose(psi, psi_ad, rtol=1e-12)
    flat, _ = jax.flatten_util.ravel_pytree(eqx.filter(grad.scene, eqx.is_inexact_array))
    assert flat.shape == flat_ad.shape
    assert np.max(np.abs(flat - flat_ad)) <= ADJOINT_VS_AUTODIFF * np.max(np.abs(flat_ad))
