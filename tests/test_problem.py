"""The public problem type (issue 12): objectives of positions and velocities with a terminal term,
gradients with respect to every array of a problem, compiled once, and clear errors for bad problems.

Two mechanisms serve every test, each compiled once per program (module-scoped fixtures):
- rigid: the README's crank–arm (driven crank, arm on its pin, spring–damper, harmonic force,
  gravity; one degree of freedom), gradients with respect to the spring constants, the force
  magnitude, body data, the objective's target point and the initial state;
- flexible: a small flexible pendulum (the designed rod pinned at A, swinging under gravity),
  gradients with respect to the densities.

The objective is `a int T dt + b |r_P(t1) - r*|^2` with array weights `(a, b)`, so that the
kinetic-energy integral `(1, 0)`, the terminal tracking term `(0, 1)` and their sum `(1, 1)` run
through the same compiled programs.

By default the adjoint's gradients are checked against central differences on every entry (every
scalar of the rigid problem, every density of the flexible one), which reuse the compiled forward
program; against autodiff (a program of its own per mechanism, ~35 s to compile) under `-m slow`.
"""

from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CRANK_ARM_POSITIONS, crank_arm_scene

import ffr_jax as fj
from ffr_jax import _api

RTOL, ATOL = 1e-10, 1e-12  # forward tolerances of every solve
# Backward tolerances: the adjoint variables are of the size of the objective's derivatives
# (1e-3..1 here), so atol 1e-12 is far below them.
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-12)
# Adjoint vs autodiff: two discretisations of the same derivative, each accurate to about the
# solver tolerances (1e-10) times the conditioning of the motion over the horizon; 1e-6 of the
# largest entry leaves a wide margin and still catches any missing term (a wrong sign or a
# dropped velocity or terminal term changes entries at the 1e-2..1 level).
ADJOINT_VS_AUTODIFF = 1e-6
# Central differences with a relative step h = 1e-4: truncation ~ h^2 |p^3 psi'''| / |p psi'| ~ 1e-8
# and solver noise ~ rtol |psi| / (h |p psi'|) ~ 1e-10 / 1e-4 = 1e-6 relative; 1e-5 bounds both.
FD_STEP = 1e-4
FD_RTOL = 1e-5
WEIGHTS = {"kinetic energy": (1.0, 0.0), "terminal tracking": (0.0, 1.0), "sum": (1.0, 1.0)}


def _weighted_objective(a, b, body, marker, target):
    return fj.Objective(integrand=fj.Scaled(fj.KineticEnergy(), a),
                        terminal=fj.Scaled(fj.MarkerTracking(body, marker, fj.FixedPoint(target)), b))


def _with_weights(problem, weights):
    # Strongly typed float64, like the weights `fj.Scaled` stores: a weakly typed array (`jnp.asarray(1.0)`)
    # would make every compiled program of the base problem compile again for its variants.
    return eqx.tree_at(lambda p: (p.objective.integrand.weight, p.objective.terminal.weight), problem,
                       tuple(jnp.asarray(w, dtype=float) for w in weights))


# --- the rigid mechanism ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def rigid():
    problem = fj.Problem(crank_arm_scene(), 1.0, positions=CRANK_ARM_POSITIONS, velocities=[0.5],
                         objective=_weighted_objective(1.0, 1.0, 1, 1, (0.25, -0.3)))
    return problem


@pytest.fixture(scope="module")
def rigid_gradients(rigid):
    """The adjoint's `(psi, grad)` for each weighting (one compiled program: the weights are arrays)."""
    return {name: {"adjoint": fj.value_and_grad(_with_weights(rigid, weights), method=ADJOINT, rtol=RTOL, atol=ATOL)}
            for name, weights in WEIGHTS.items()}


# Automatic differentiation in forward mode (`jax.jacfwd` through the solver, diffrax's `ForwardMode`): the exact
# derivative of the discrete forward solution, the one `jax.grad` through the solver (`method="autodiff"`) gives,
# without compiling a reverse pass (the autodiff programs were ~35 s of compile each on two loaded cores). `psi` comes
# from the same forward solve as the adjoint's (same solver, tolerances, steps).
@eqx.filter_jit
def _forward_mode_problem(problem):
    """`(psi, d psi / d p)` over every float entry `p` of `problem` (flat, in the order of `_flat`)."""
    dynamic, static = eqx.partition(problem, eqx.is_inexact_array)
    flat, unravel = jax.flatten_util.ravel_pytree(dynamic)

    def both(p):
        value = fj.simulate(eqx.combine(unravel(p), static), rtol=RTOL, atol=ATOL, adjoint=diffrax.ForwardMode()).psi
        return value, value

    grad, psi = jax.jacfwd(both, has_aux=True)(flat)
    return psi, grad


@eqx.filter_jit
def _forward_mode_design(case, x):
    """`(psi, d psi / d x)` of a case at design `x`."""
    def both(y):
        value = fj.simulate(case, y, rtol=RTOL, atol=ATOL, adjoint=diffrax.ForwardMode()).psi
        return value, value

    grad, psi = jax.jacfwd(both, has_aux=True)(x)
    return psi, grad


@pytest.fixture(scope="module")
def rigid_autodiff(rigid):
    return {name: _forward_mode_problem(_with_weights(rigid, weights)) for name, weights in WEIGHTS.items()}


def _flat(grad):
    """Every derivative of a problem-shaped gradient as one vector."""
    return np.asarray(jax.flatten_util.ravel_pytree(eqx.filter(grad, eqx.is_inexact_array))[0])


def _central_difference(problem, where, index, step):
    leaf = where(problem)
    h = step * max(abs(float(leaf[index])), 1e-2)
    plus = eqx.tree_at(where, problem, leaf.at[index].add(h))
    minus = eqx.tree_at(where, problem, leaf.at[index].add(-h))
    return (float(fj.objective(plus, rtol=RTOL, atol=ATOL)) - float(fj.objective(minus, rtol=RTOL, atol=ATOL))) / (2 * h)


def _every_entry(problem):
    """`(label, value, perturbed)` for every scalar of every float array of `problem`: `perturbed(h)` is the
    problem with that scalar moved by `h` (in place, so dtypes and weak types, and so the compiled
    programs, stay those of `problem`)."""
    dynamic, static = eqx.partition(problem, eqx.is_inexact_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    for i, leaf in enumerate(leaves):
        for index in np.ndindex(leaf.shape):
            def perturbed(h, i=i, index=index):
                moved = list(leaves)
                moved[i] = leaves[i].at[index].add(h)
                return eqx.combine(jax.tree_util.tree_unflatten(treedef, moved), static)
            yield (i, index), float(leaf[index]), perturbed


# Every derivative of psi with respect to every array of the problem (spring and damper constants,
# force law, body data, the objective's weights and target, the initial state: 53 scalars) against
# central differences, for each weighting, so that neither the integral nor the terminal part can hide
# in the other. Central differences are independent of both gradient routes and cheap here (about 320
# solves of the compiled forward program, a few seconds); the comparison with autodiff (an autodiff
# program of its own, ~35 s to compile) is in the slow test below.
@pytest.mark.parametrize("objective", list(WEIGHTS))
def test_rigid_adjoint_equals_central_differences_on_every_parameter(rigid, rigid_gradients, objective):
    problem = _with_weights(rigid, WEIGHTS[objective])
    psi, grad = rigid_gradients[objective]["adjoint"]
    g = _flat(grad)
    entries = list(_every_entry(problem))
    assert len(entries) == g.size, "the gradient has one entry per scalar of the problem's float arrays"
    scale = np.max(np.abs(g))
    for (label, value, perturbed), adjoint in zip(entries, g):
        h = FD_STEP * max(abs(value), 1e-2)
        fd = (float(fj.objective(perturbed(h), rtol=RTOL, atol=ATOL))
              - float(fj.objective(perturbed(-h), rtol=RTOL, atol=ATOL))) / (2 * h)
        # FD_RTOL as for the scalars of the other tests, plus the solver noise of a difference quotient,
        # rtol |psi| / h, with a factor 10: it dominates where the step is absolute (scalars that are zero,
        # such as the ground pin at the origin: h = 1e-6) and the derivative small beside psi (there the
        # quotient moved by 7e-9 = 1e-10 * 0.07 / 1e-6 with the forward tolerance, measured). A missing term
        # moves an entry by 1e-2..1 of it, far above both.
        tolerance = FD_RTOL * max(abs(fd), 1e-3 * scale) + 10 * RTOL * abs(float(psi)) / h
        assert abs(adjoint - fd) <= tolerance, (
            f"{objective}, d psi / d (leaf, index) {label}: adjoint {adjoint:.10e}, central differences {fd:.10e}")


@pytest.mark.slow  # a forward-mode program of its own; central differences check every entry by default
@pytest.mark.parametrize("objective", list(WEIGHTS))
def test_rigid_adjoint_equals_autodiff_for_every_parameter(rigid_gradients, rigid_autodiff, objective):
    adjoint, autodiff = rigid_gradients[objective]["adjoint"], rigid_autodiff[objective]
    # psi of both comes from the same forward solve (same solver, tolerances, steps): equal up to the
    # round-off of differently compiled sums (measured: identical).
    np.testing.assert_allclose(float(adjoint[0]), float(autodiff[0]), rtol=1e-12, err_msg="psi")
    g_adj, g_ad = _flat(adjoint[1]), np.asarray(autodiff[1])
    assert g_adj.shape == g_ad.shape, "the adjoint and forward mode differentiate the same float entries"
    err = np.max(np.abs(g_adj - g_ad)) / np.max(np.abs(g_ad))
    assert err <= ADJOINT_VS_AUTODIFF, f"{objective}: adjoint vs autodiff, max error {err:.2e} of max |grad|"


@pytest.mark.slow  # two compiles of their own (backsolve, direct); the same methods run on cases in test_sensitivity
def test_every_method_takes_a_problem(rigid, rigid_gradients):
    """Backsolve and the direct method on the sum objective, against the adjoint."""
    reference = _flat(rigid_gradients["sum"]["adjoint"][1])
    for method in (fj.Backsolve(rtol=1e-10, atol=1e-12), "direct"):
        psi, grad = fj.value_and_grad(rigid, method=method, rtol=RTOL, atol=ATOL)
        err = np.max(np.abs(_flat(grad) - reference)) / np.max(np.abs(reference))
        # Backsolve integrates the state backward as well (its error grows with the horizon's
        # conditioning): 1e-5 of max |grad| at these tolerances.
        assert err <= 1e-5, f"{method}: max error {err:.2e} of max |grad| against the adjoint"


def test_plain_calls_are_compiled_once(rigid):
    fj.value_and_grad(rigid, method=ADJOINT, rtol=RTOL, atol=ATOL)
    size = _api._value_and_grad_problem._jitted._cached._cache_size()
    stiffer = eqx.tree_at(lambda p: p.scene.forces[0].stiffness, rigid, jnp.asarray(250.0))
    fj.value_and_grad(stiffer, method=ADJOINT, rtol=RTOL, atol=ATOL)
    assert _api._value_and_grad_problem._jitted._cached._cache_size() == size, "a new spring constant recompiled"


def test_trajectory_holds_every_coordinate_and_marker(rigid):
    ts = jnp.linspace(0.0, 1.0, 11)
    traj = fj.simulate(rigid, ts=ts, rtol=RTOL, atol=ATOL)
    scene, model = rigid.scene, rigid.model
    assert traj.positions.shape == (11, scene.n_coordinates) and traj.velocities.shape == (11, scene.n_coordinates)
    for k in range(ts.size):
        # The dependent coordinates come from Newton's method to 1e-13 and the velocities from a
        # linear solve: the constraints hold to round-off (1e-12 of the coordinates' size ~ 1).
        c = scene.constraint_residual(ts[k], traj.positions[k])
        cdot = model.velocity_constraint(ts[k], traj.positions[k], traj.velocities[k], scene)
        assert np.max(np.abs(c)) < 1e-11 and np.max(np.abs(cdot)) < 1e-11, f"constraints at t = {ts[k]}"
    tip = traj.marker_positions(scene, 1, 1)
    expected = np.stack([np.asarray(scene.marker_position(1, 1, y_r)) for y_r in traj.positions])
    # The same marker function evaluated twice (vectorised and one state at a time), on coordinates of
    # size ~1: round-off only (measured: identical).
    np.testing.assert_allclose(tip, expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(traj.ys[:, 0], traj.positions[:, 5], rtol=0, atol=0)
    assert float(traj.psi) == pytest.approx(float(fj.objective(rigid, rtol=RTOL, atol=ATOL)), rel=1e-12)


# --- the flexible mechanism -------------------------------------------------------------------
@pytest.fixture(scope="module")
def flexible():
    case = fj.cases.flexible_pendulum(8, 2, 2, 0.1)
    # The free end B (marker 1) swings down from (0.71, -0.71); the target lies on its way.
    return case.with_objective(_weighted_objective(1.0, 1.0, 0, 1, (0.6, -0.8)))


@pytest.fixture(scope="module")
def flexible_gradients(flexible):
    """A random design, and per weighting the case and the adjoint's `(psi, grad)` (one compiled program)."""
    x = jnp.asarray(np.random.default_rng(0).uniform(0.3, 0.9, flexible.n_design))
    out = {}
    for name, weights in WEIGHTS.items():
        case = eqx.tree_at(lambda c: c.problem, flexible, _with_weights(flexible.problem, weights))
        out[name] = (case, fj.value_and_grad(case, x, ADJOINT, rtol=RTOL, atol=ATOL))
    return x, out


@pytest.mark.parametrize("objective", list(WEIGHTS))
def test_flexible_design_gradient_equals_central_differences_on_every_entry(flexible_gradients, objective):
    """The design gradient for each weighting against central differences on every density (as for the
    rigid mechanism: independent of both gradient routes, and with the parts separate neither hides in the
    sum); the comparison with autodiff is the slow test below."""
    x, out = flexible_gradients
    case, (_, grad) = out[objective]
    g = np.asarray(grad)
    scale = np.max(np.abs(g))
    assert scale > 0
    for k in range(x.size):
        h = FD_STEP
        fd = (float(fj.objective(case, x.at[k].add(h), rtol=RTOL, atol=ATOL))
              - float(fj.objective(case, x.at[k].add(-h), rtol=RTOL, atol=ATOL))) / (2 * h)
        assert abs(fd - g[k]) <= FD_RTOL * max(abs(fd), 1e-2 * scale), (
            f"{objective}, entry {k}: adjoint {g[k]:.10e}, central differences {fd:.10e}")


@pytest.mark.slow  # a forward-mode program of its own; central differences check every entry by default
@pytest.mark.parametrize("objective", list(WEIGHTS))
def test_flexible_design_gradient_adjoint_equals_autodiff(flexible_gradients, objective):
    x, out = flexible_gradients
    case, (_, adjoint) = out[objective]
    g_adj = np.asarray(adjoint)
    g_ad = np.asarray(_forward_mode_design(case, x)[1])  # automatic differentiation, forward mode (above)
    err = np.max(np.abs(g_adj - g_ad)) / np.max(np.abs(g_ad))
    assert err <= ADJOINT_VS_AUTODIFF, f"{objective}: adjoint vs autodiff, max error {err:.2e} of max |grad|"


# --- bad problems -----------------------------------------------------------------------------
def _problem(objective, **kwargs):
    kwargs.setdefault("positions", CRANK_ARM_POSITIONS)
    return fj.Problem(crank_arm_scene(), 1.0, objective=objective, **kwargs)


def test_objective_must_return_a_scalar():
    with pytest.raises(ValueError, match="must return a scalar"):
        _problem(fj.FunctionIntegrand(lambda t, y_r, z_r, scene: z_r[:2] ** 2))


def test_objective_must_be_finite():
    with pytest.raises(ValueError, match="finite"):
        _problem(fj.FunctionIntegrand(lambda t, y_r, z_r, scene: jnp.log(y_r[0] - 1.0)))


def test_terminal_term_on_coordinates_the_constraints_fix():
    """The crank's tip is fixed by the pivot and the driver: a terminal term on it cannot see the motion."""
    with pytest.raises(ValueError, match="constraints fix"):
        _problem(fj.Objective(terminal=fj.MarkerTracking(0, 1, (0.0, 0.1))))


def test_inconsistent_initial_velocities():
    velocities = np.zeros(6)
    velocities[3] = 1.0  # the arm's pin moving although the crank is at rest
    with pytest.raises(ValueError, match="Inconsistent initial velocities"):
        _problem(fj.KineticEnergy(), velocities=velocities)


def test_positions_that_cannot_be_assembled():
    scene = crank_arm_scene()
    # The arm's tip (0.4 from the crank pin) on the vertical line x = 5: out of reach.
    scene = eqx.tree_at(lambda s: s.constraints, scene, scene.constraints + (
        fj.PointOnLine(body=1, marker=1, point=(5.0, 0.0), direction=(0.0, 1.0)),))
    # The refusal names the constraints left violated at the closest (least-squares) configuration, the
    # unreachable point-on-line among them.
    with pytest.raises(ValueError, match=r"cannot be assembled at the initial state(.|\n)*PointOnLine"):
        fj.Problem(scene, 1.0, positions=CRANK_ARM_POSITIONS, objective=fj.KineticEnergy())


@pytest.mark.parametrize("bad, match", [
    (dict(positions=np.zeros(5)), "shape"),
    (dict(positions=np.full(6, np.nan)), "NaN"),
    (dict(velocities=[np.inf]), "NaN or inf"),
])
def test_bad_initial_state_arrays(bad, match):
    with pytest.raises(ValueError, match=match):
        _problem(fj.KineticEnergy(), **bad)


@pytest.mark.parametrize("t1", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_time_span(t1):
    with pytest.raises(ValueError, match="t1"):
        fj.Problem(crank_arm_scene(), t1, positions=CRANK_ARM_POSITIONS, objective=fj.KineticEnergy())


def test_problem_has_no_design_vector(rigid):
    with pytest.raises(ValueError, match="no design vector"):
        fj.value_and_grad(rigid, jnp.ones(3))


@pytest.mark.parametrize("field, value, match", [
    ("mass", -1.0, "mass must be positive"),
    ("inertia", 1e-6, "parallel-axis"),
    ("first_moment", np.zeros(3), "first_moment"),
])
def test_body_data_is_validated(field, value, match):
    good = dict(mass=1.0, first_moment=(0.2, 0.0), inertia=0.1, marker_positions=[[0.0, 0.0]])
    good[field] = value
    # A wrong shape meets the test suite's jaxtyping hook (pyproject addopts) before BodyData's own
    # check, which is what a user without the hook gets; both name the field.
    with pytest.raises((ValueError, TypeError), match=match):
        fj.rigid_body_data(**good)


def test_flexible_body_data_is_validated(flexible):
    data = flexible.scene_template.bodies[0].data
    fields = {f: getattr(data, f) for f in data.__dataclass_fields__}
    fields["modal_mass"] = fields["modal_mass"].at[0, 1].add(0.5)
    with pytest.raises(ValueError, match="modal_mass must be symmetric"):
        fj.BodyData(**fields)


def test_applied_force_direction_is_checked():
    with pytest.raises(ValueError, match="direction"):
        fj.AppliedForce(0, 0, 1.0, direction=(0.0, 0.0))


# --- the README's own mechanism ---------------------------------------------------------------
def _readme_block(heading: str) -> str:
    # The README's "Your own mechanism" moved to the docs page on problems and scenes (issue 29).
    text = (Path(__file__).parent.parent / "docs" / "concepts" / "problem.md").read_text()
    section = text[text.index(heading):]
    return section[section.index("```python") + len("```python"):section.index("```", section.index("```python") + 9)]


def test_readme_own_mechanism_runs_and_its_gradient_is_right(capsys):
    """The README's "Your own mechanism" block, run as written; its spring-constant derivative against
    central differences (step 1e-4 relative: see FD_RTOL).

    The differences are taken on the same mechanism and objective written in the form of the `rigid`
    fixture (`a int T dt + b |r_P(t1) - r*|^2` with `(a, b) = (1, 0)`, released at rest), so that they
    run through the forward program compiled for it instead of compiling one more."""
    namespace = {}
    exec(compile(_readme_block("## Your own mechanism"), "docs/concepts/problem.md", "exec"), namespace)
    problem, grad = namespace["problem"], namespace["grad"]
    assert problem.scene.n_coordinates == 6 and problem.n_independent == 1
    same = fj.Problem(crank_arm_scene(), 1.0, positions=CRANK_ARM_POSITIONS, velocities=[0.0],
                      objective=_weighted_objective(1.0, 0.0, 1, 1, (0.25, -0.3)))
    # The same psi: two solves of one motion at forward rtol 1e-10, differently compiled (so possibly with
    # other step decisions), each accurate to about that times the growth of the error over the run: 1e-8.
    assert float(fj.objective(same, rtol=RTOL, atol=ATOL)) == pytest.approx(float(namespace["psi"]), rel=1e-8)
    fd = _central_difference(same, lambda p: p.scene.forces[0].stiffness, (), FD_STEP)
    adjoint = float(grad.scene.forces[0].stiffness)
    assert abs(adjoint - fd) <= FD_RTOL * abs(fd), f"README: dpsi/dk adjoint {adjoint:.10e}, differences {fd:.10e}"
    assert str(namespace["psi"].item())[:6] in capsys.readouterr().out
