"""The design map: designs of one or several bodies -> the scene; the case's forwards; dict designs.

A two-body case (a flexible double pendulum: two rods, gravity) shows the dict design end to end:
the adjoint gradient is a dict with one array per body, computed by one forward and one backward
solve, and equals central finite differences on entries of each body.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_close_relative, small_case

import ffr_jax as fj
from ffr_jax._design.geometry import rod_joint_nodes
from ffr_jax._design.mesh import StructuredGrid
import ffr_jax._design as fd

# The two-body gradient check: psi is about 8e-6 and the elastic coordinates about 1e-6 here, so the
# solves run at absolute tolerances scaled to that (forward atol 1e-15; backward rtol 1e-10, atol
# 1e-15; with the defaults, 1e-12 and 1e-10, the adjoint is off by 3e-6 of max |grad|). Central
# differences with step 1e-4 on densities in [0.3, 0.9] of psi at rtol 1e-12: truncation
# h^2 / 6 |d3 psi| ~ 1e-7 and round-off 1e-12 psi / h ~ 1e-8 of max |grad| (measured: up to 1.4e-7).
TWO_BODY_RTOL = 1e-6
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-15)
FORWARD_ATOL = 1e-15
FD_STEP = 1e-4


def _double_pendulum(t1: float = 0.05):
    """Two small rods (6 x 2 and 8 x 2, one mode each) hanging from a ground pivot, released from rest."""
    upper = fj.cases.rod_body(6, 2, 1, modal_solver=fd.DenseModes())
    lower = fj.cases.rod_body(8, 2, 1, length=0.8, modal_solver=fd.DenseModes())
    scene = fj.Scene(
        bodies=(fj.Body("upper", upper.uniform_body_data()), fj.Body("lower", lower.uniform_body_data())),
        constraints=(fj.GroundRevolute(body=0, marker=0), fj.Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0)),
        forces=(fj.Gravity((0.0, -9.81)),),
    )
    theta_1, theta_2 = -np.pi / 4, -np.pi / 3
    positions = [0.0, 0.0, theta_1, 0.0, np.cos(theta_1), np.sin(theta_1), theta_2, 0.0]
    problem = fj.Problem(scene, t1, positions=positions, objective=fj.Compliance(body=0) + fj.Compliance(body=1))
    return fj.Case(problem, fj.DesignMap({"upper": upper, "lower": lower}))


def _designs(case, seed):
    rng = np.random.default_rng(seed)
    return {name: jnp.asarray(rng.uniform(0.3, 0.9, n)) for name, n in case.design_map.design_sizes.items()}


@pytest.fixture(scope="module")
def two_body():
    """The case, a design, its adjoint `(psi, grad)`, and the number of diffrax solves traced for it."""
    case = _double_pendulum()
    x = _designs(case, 0)
    solves = []
    original = diffrax.diffeqsolve

    def counting(*args, **kwargs):
        solves.append(1)
        return original(*args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(diffrax, "diffeqsolve", counting)
        psi, grad = fj.value_and_grad(case, x, ADJOINT, atol=FORWARD_ATOL)
    return case, x, psi, grad, len(solves)


# --- layout and forms -------------------------------------------------------------------------------


def test_designs_come_as_a_dict_by_body_or_flat_for_one_body(two_body):
    case = two_body[0]
    dmap = case.design_map
    assert dmap.names == ("lower", "upper") and dmap.design_sizes == {"upper": 8, "lower": 12}
    assert case.n_design == 20
    x = case.initial_design(0.5)
    assert set(x) == {"upper", "lower"} and x["upper"].shape == (8,) and x["lower"].shape == (12,)
    mixed = case.initial_design({"upper": 0.3, "lower": 0.9})
    assert float(mixed["upper"][0]) == 0.3 and float(mixed["lower"][0]) == 0.9
    # Results per body in the form of the design (shapes only: the numbers are each body's own).
    freqs = jax.eval_shape(case.frequencies, x)
    assert set(freqs) == {"upper", "lower"} and freqs["upper"].shape == (1,)
    data = jax.eval_shape(case.body_data, x)
    assert data["lower"].marker_positions.shape == (2, 2)
    # One designed body: a flat array works, and a dict gives a dict.
    rod = small_case()
    flat = rod.initial_design(0.5)
    assert flat.shape == (rod.n_design,) and jax.eval_shape(rod.frequencies, flat).shape == (4,)
    assert jax.eval_shape(rod.frequencies, {"rod": flat})["rod"].shape == (4,)


def test_bad_designs_are_clear_errors_naming_the_body(two_body):
    case = two_body[0]
    x = case.initial_design(0.5)
    with pytest.raises(ValueError, match=r"no entry for the designed body 'lower'"):
        case.check({"upper": x["upper"]})
    with pytest.raises(ValueError, match=r"entries for 'rocker', which is not a designed body"):
        case.check({**x, "rocker": x["upper"]})
    with pytest.raises(ValueError, match=r"Design vector has shape \(9,\), expected \(8,\) for body 'upper'"):
        case.check({**x, "upper": jnp.full(9, 0.5)})
    with pytest.raises(ValueError, match=r"2 designed bodies \['lower', 'upper'\]: pass the design as a dict"):
        case.check(jnp.full(20, 0.5))
    with pytest.raises(ValueError, match="no entry for the designed body 'lower'"):
        case.initial_design({"upper": 0.5})
    # At trace time, before anything is computed or compiled:
    with pytest.raises(ValueError, match=r"expected \(12,\) for body 'lower'"):
        fj.value_and_grad(case, {**x, "lower": jnp.full(11, 0.5)})
    # Values at run time, with the body named.
    bad = {**x, "lower": x["lower"].at[3].set(jnp.nan)}
    # (a concrete design is checked on the host at once: ffr_jax.DesignError; a traced one at run time)
    with pytest.raises((fj.DesignError, eqx.EquinoxRuntimeError, RuntimeError),
                       match=r"Design vector contains NaN or inf for body 'lower'"):
        jax.block_until_ready(case.check(bad))
    bad = {**x, "upper": x["upper"].at[0].set(1.5)}
    with pytest.raises((fj.DesignError, eqx.EquinoxRuntimeError, RuntimeError),
                       match=r"\[x_min, 1\] = \[0.01, 1\] for body 'upper'"):
        jax.block_until_ready(case.check(bad))


def test_design_map_and_case_refuse_bad_structure():
    body = fj.cases.rod_body(6, 2, 1, modal_solver=fd.DenseModes())
    with pytest.raises(TypeError, match="takes a dict"):
        fj.DesignMap(body)
    with pytest.raises(TypeError, match="must be a DesignedBody"):
        fj.DesignMap({"rod": 3})
    rod = small_case()
    with pytest.raises(ValueError, match="No body named 'coupler'"):
        fj.Case(rod.problem, fj.DesignMap({"coupler": body}))
    with pytest.raises(ValueError, match="has 4 shape vectors and 2 markers, but its DesignedBody gives 1 and 2"):
        fj.Case(rod.problem, fj.DesignMap({"rod": body}))
    with pytest.raises(ValueError, match="2 designed bodies"):
        _double_pendulum().design


# --- the one-body forwards (the rod) ---------------------------------------------------------------


def test_the_rod_case_forwards_its_designed_body():
    case = small_case()
    body = case.design
    assert isinstance(body, fj.DesignedBody) and isinstance(case.mesh, StructuredGrid)
    assert (case.mesh.nx, case.mesh.ny, case.n_modes) == (12, 2, 4) and case.n_design == 2 * 10
    assert case.marker_nodes == rod_joint_nodes(12, 2) and case.material == fj.SIMP()
    a, b = case.marker_nodes
    assert case.fixed_dofs == (2 * a, 2 * a + 1, 2 * b + 1), "hinged-hinged: u_x(A), u_y(A), u_y(B)"
    x = jnp.linspace(0.2, 0.9, case.n_design)
    np.testing.assert_array_equal(case.design_grid(x), np.asarray(x).reshape(2, 10))
    k, m = case.fe_matrices(x)
    assert k.shape == m.shape == (case.mesh.n_dof, case.mesh.n_dof)
    filt = fj.DensityFilter(case.design, 1.5)
    assert filt.weights.shape[0] == case.n_design


# --- gradients of a dict design ------------------------------------------------------------------------


def test_dict_gradient_by_one_forward_and_one_backward_solve(two_body):
    case, x, psi, grad, solves = two_body
    assert solves == 2, f"value_and_grad traced {solves} diffrax solves; one forward and one backward expected"
    assert set(grad) == {"upper", "lower"}
    for name in grad:
        assert grad[name].shape == x[name].shape and np.all(np.isfinite(np.asarray(grad[name])))
    assert float(psi) > 0.0


def test_dict_gradient_equals_finite_differences_on_each_body(two_body):
    case, x, psi, grad, _ = two_body
    objective = eqx.filter_jit(lambda case, x: fj.objective(case, x, rtol=1e-12, atol=1e-16))
    np.testing.assert_allclose(objective(case, x), psi, rtol=1e-8, err_msg="psi at rtol 1e-12 and 1e-10")
    scale = max(float(np.abs(g).max()) for g in grad.values())
    for name in ("upper", "lower"):
        for e in np.argsort(-np.abs(np.asarray(grad[name])))[:2]:
            plus = {**x, name: x[name].at[e].add(FD_STEP)}
            minus = {**x, name: x[name].at[e].add(-FD_STEP)}
            fd_ = (objective(case, plus) - objective(case, minus)) / (2 * FD_STEP)
            assert abs(float(grad[name][e]) - float(fd_)) <= TWO_BODY_RTOL * scale, \
                f"d psi / d x[{name!r}][{e}]: adjoint {float(grad[name][e]):.6e}, central differences {float(fd_):.6e}"


def test_design_map_vjp_returns_the_structure_of_the_design():
    """The pullback of the scene through the design map: a dict for a dict, an array for an array, the same numbers."""
    case = small_case()
    x = jnp.asarray(np.random.default_rng(3).uniform(0.3, 0.9, case.n_design))

    @eqx.filter_jit
    def pullbacks(case, x):
        out = []
        for design in (x, {"rod": x}):
            scene, vjp = eqx.filter_vjp(case.scene, design)
            cotangent = jax.tree_util.tree_map(jnp.ones_like, eqx.filter(scene, eqx.is_inexact_array))
            out.append(vjp(cotangent)[0])
        return out

    flat, by_body = pullbacks(case, x)
    assert set(by_body) == {"rod"}
    assert_close_relative(by_body["rod"], flat, 1e-14, "VJP of the design map, dict vs flat design")


# --- modal solvers through the whole case, batches across devices --------------------------------------


@pytest.mark.slow  # two adjoint compiles; benchmarks/bench_design_map.py compares the reference case's numbers
def test_dense_and_lanczos_modes_give_the_same_psi_and_gradient():
    """The modal solvers solve the same eigenproblem by different algorithms (LAPACK vs ARPACK + SuperLU, and
    their derivatives); psi and the adjoint gradient agree to 1e-9 / 1e-8 (the Lanczos complement solves
    stop at a relative residual of 1e-12, amplified by the eigenvalue gaps)."""
    dense = fj.cases.slider_crank(12, 2, 4, 0.2, modal_solver=fd.DenseModes())
    lanczos = fj.cases.slider_crank(12, 2, 4, 0.2, modal_solver=fd.LanczosModes())
    x = jnp.asarray(np.random.default_rng(4).uniform(0.2, 0.95, dense.n_design))
    # The paper's adjoint at its tolerances (the default route would pick the discrete adjoint at rtol 1e-7 for this
    # 0.2 s span, whose step sequence the 1e-12 differences between the modal solvers can change).
    psi_d, grad_d = fj.value_and_grad(dense, x, "adjoint")
    psi_l, grad_l = fj.value_and_grad(lanczos, x, "adjoint")
    assert_close_relative(psi_l, psi_d, 1e-9, "psi")
    assert_close_relative(grad_l, grad_d, 1e-8, "adjoint gradient of psi")


@pytest.mark.slow
def test_largest_rod_frequencies():
    """1000 x 100 elements, 99,800 design variables: within 10 % of the converged rod (the reference
    mesh's 32.6 ... 726 Hz; the fine mesh has no Q4 locking to speak of at dx / dy = 1)."""
    case = fj.cases.slider_crank(1000, 100, 6, 0.2)
    assert case.n_design == 99_800
    f = np.asarray(case.frequencies(case.initial_design(0.5)))
    reference = np.array([32.552, 128.09, 280.89, 291.47, 483.06, 726.15])
    assert np.all(np.abs(f - reference) / reference < 0.1), f


_SHARDED_SCRIPT = """
import jax, jax.numpy as jnp, numpy as np
import ffr_jax
assert len(jax.devices()) == 2, jax.devices()
rng = np.random.default_rng(0)
for solver, nx, ny in ((ffr_jax.DenseModes(), 12, 2), (ffr_jax.LanczosModes(), 20, 4)):
    case = ffr_jax.cases.slider_crank(nx, ny, 4, 0.2, modal_solver=solver)

    def f(x):
        gradient = jax.grad(lambda x: jnp.trace(case.body_data(x).modal_stiffness))(x)
        return case.frequencies(x), case.body_data(x).mass, gradient

    one = jax.jit(f)
    sharded = ffr_jax.sharded_map(f)
    for batch in (4, 3):  # 3: padded to a multiple of the device count
        xs = jnp.asarray(rng.uniform(0.2, 0.95, (batch, case.n_design)))
        out = sharded(xs)
        assert all(o.shape[0] == batch for o in out)
        for b in range(batch):
            for name, got, want in zip(("frequencies", "mass", "gradient"), out, one(xs[b])):
                err = np.max(np.abs(np.asarray(got[b]) - np.asarray(want))) / np.max(np.abs(np.asarray(want)))
                assert err < 1e-10, (type(solver).__name__, batch, b, name, err)
print("SHARDED OK")
"""


def test_sharded_batch_equals_loop_over_designs():
    """On two forced host devices, `sharded_map` equals a loop of single-design calls, both modal solvers."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    result = subprocess.run([sys.executable, "-c", _SHARDED_SCRIPT], env=env, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0 and "SHARDED OK" in result.stdout, result.stdout + result.stderr
