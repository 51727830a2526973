"""Gradients of a spatial rigid problem (issue 26, first part): the paper's adjoint against central
differences (default) and against automatic differentiation through the solver (`-m slow`).

The mechanism: a rigid body on a spherical joint at its frame origin, swinging and spinning under
gravity and a spring from one of its markers to a ground point. The objective
`psi = int T dt + z_P(t1)` (kinetic energy and the final height of a marker) has an integrand and a
terminal term. Parameters: the body data (first moment, inertia tensor, mass), the spring constant and
the initial state.
"""

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj

RTOL, ATOL = 1e-10, 1e-12
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-12)
# Adjoint vs autodiff: two discretisations of the same derivative, each accurate to about the solver
# tolerance (1e-10) times the conditioning of the motion over 0.5 s; 1e-6 of the largest entry leaves a wide
# margin and still catches a missing term (a wrong sign of the gyroscopic forces changes entries at 1e-1).
ADJOINT_VS_AUTODIFF = 1e-6
# Central differences with relative step h = 1e-4: truncation ~ h^2 ~ 1e-8 relative, solver noise
# ~ rtol |psi| / (h |theta dpsi/dtheta|) ~ 1e-10 / 1e-4 = 1e-6 relative; 1e-5 of the largest entry bounds both.
FD_STEP, FD_RTOL = 1e-4, 1e-5


def _problem() -> fj.Problem:
    m, l = 1.5, 0.4
    s = np.array([0.05, 0.0, -m * l])
    j_origin = np.diag([0.02, 0.03, 0.015]) + ((s @ s) * np.eye(3) - np.outer(s, s)) / m  # parallel axes
    data = fj.spatial_rigid_body_data(m, s, j_origin, [[0.0, 0.0, 0.0], [0.1, 0.05, -0.5]])
    spring = fj.SpringDamper(0, 1, stiffness=20.0, rest_length=0.3, ground_point=(0.3, 0.2, -0.4))
    scene = fj.Scene(bodies=(fj.Body("bob", data),), constraints=(fj.SphericalJoint(0, 0),),
                     forces=(fj.Gravity((0.0, 0.0, -9.81)), spring))
    p0 = fj.euler_parameters((1.0, 1.0, 0.0), 0.4)
    rates = np.asarray(fj.euler_parameter_rates(p0, [0.5, -1.0, 2.0]))
    objective = fj.Objective(integrand=fj.KineticEnergy(),
                             terminal=fj.FunctionIntegrand(lambda t, y_r, z_r, scene: scene.marker_position(0, 1, y_r)[2]))
    return fj.Problem(scene, 0.5, positions=np.concatenate([np.zeros(3), p0]), velocities=rates, objective=objective)


# Directions in the problem's parameters: (name, selector of the array, entries perturbed together).
DIRECTIONS = (
    ("J_xx", lambda p: p.scene.bodies[0].data.inertia, ((0, 0),)),
    ("J_zz", lambda p: p.scene.bodies[0].data.inertia, ((2, 2),)),
    ("J_xy (symmetric)", lambda p: p.scene.bodies[0].data.inertia, ((0, 1), (1, 0))),
    ("s_x", lambda p: p.scene.bodies[0].data.first_moment, ((0,),)),
    ("s_z", lambda p: p.scene.bodies[0].data.first_moment, ((2,),)),
    ("spring stiffness", lambda p: p.scene.forces[1].stiffness, ((),)),
    ("y0[1] (e1)", lambda p: p.y0, ((1,),)),
    ("z0[3] (e3')", lambda p: p.z0, ((3,),)),
)


def _directional(tree, select, entries):
    """`sum` of the selected array's entries (the derivative along the direction)."""
    a = select(tree)
    return sum(float(a[e]) for e in entries)


def _perturbed(problem, select, entries, delta):
    a = select(problem)
    for e in entries:
        a = a.at[e].add(delta)
    return eqx.tree_at(select, problem, a)


@pytest.fixture(scope="module")
def adjoint():
    problem = _problem()
    return problem, fj.value_and_grad(problem, method=ADJOINT, rtol=RTOL, atol=ATOL)


def test_adjoint_matches_central_differences(adjoint):
    """`value_and_grad(problem)` by the adjoint equals central differences of `fj.objective` along every
    direction; the mass has no effect (the body is held at its frame origin, where the mass multiplies only
    the accelerations of `R`, which the joint keeps at zero)."""
    problem, (psi, grad) = adjoint
    np.testing.assert_allclose(psi, fj.objective(problem, rtol=RTOL, atol=ATOL), rtol=1e-12)
    scale = max(abs(_directional(grad, s, e)) for _, s, e in DIRECTIONS)
    for name, select, entries in DIRECTIONS:
        h = FD_STEP * max(abs(_directional(problem, select, entries)), 1e-2)
        up = fj.objective(_perturbed(problem, select, entries, h), rtol=RTOL, atol=ATOL)
        down = fj.objective(_perturbed(problem, select, entries, -h), rtol=RTOL, atol=ATOL)
        fd = float(up - down) / (2 * h)
        got = _directional(grad, select, entries)
        assert abs(got - fd) <= FD_RTOL * scale, f"d psi / d {name}: adjoint {got}, central differences {fd}"
    assert abs(float(grad.scene.bodies[0].data.mass)) <= 1e-12 * scale


@pytest.mark.slow
def test_adjoint_matches_autodiff(adjoint):
    """The adjoint's gradient equals `jax.grad` through the solver on every array of the problem."""
    problem, (psi, grad) = adjoint
    psi_ad, grad_ad = fj.value_and_grad(problem, method="autodiff", rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(psi, psi_ad, rtol=1e-12)
    flat, _ = jax.flatten_util.ravel_pytree(eqx.filter(grad, eqx.is_inexact_array))
    flat_ad, _ = jax.flatten_util.ravel_pytree(eqx.filter(grad_ad, eqx.is_inexact_array))
    assert np.max(np.abs(flat - flat_ad)) <= ADJOINT_VS_AUTODIFF * np.max(np.abs(flat_ad))
