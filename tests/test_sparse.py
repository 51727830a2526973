"""The sparse FE path (matrix-free K and M, shift-invert Lanczos, VJP from sparse solves) and batches.

The sparse and the dense path must give the same frequencies, body data, psi and gradients on
meshes where both run. Modes differ between the paths by signs (and rotations inside clusters),
so body data are compared after aligning the sparse modes to the dense ones, and gradients are
those of quantities invariant under `Phi -> Phi Q`.
"""

import functools
import os
import subprocess
import sys
import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from helpers import assert_close_relative, random_design

import ffr_jax
from ffr_jax._fe import RodMesh, assemble
from ffr_jax._sparse_fe import SPARSE_MIN_DOF, resolve_fe_path, scipy_matrices, sparse_mass_matrix, sparse_stiffness_matrix
from ffr_jax._sparse_modes import sparse_hinged_modes


# The two paths solve the same eigenproblem with different algorithms (LAPACK vs ARPACK + SuperLU).
PATH_RTOL = 1e-9
# Gradients: the sparse complement solves stop at a relative residual of 1e-12.
GRAD_RTOL = 1e-8
# Central finite differences of smooth functionals.
FD_RTOL = 1e-6


@functools.cache
def _cases(nx: int = 20, ny: int = 4, n_modes: int = 6, t1: float = 0.2):
    dense = ffr_jax.cases.slider_crank(nx, ny, n_modes, t1, fe_path="dense")
    sparse = ffr_jax.cases.slider_crank(nx, ny, n_modes, t1, fe_path="sparse")
    return dense, sparse


# Case functions compiled once per case (op-by-op dispatch of the body-data products is slow).
_frequencies = eqx.filter_jit(lambda case, x: case.frequencies(x))
_modes = eqx.filter_jit(lambda case, x: case.modes(x))
_body_data = eqx.filter_jit(lambda case, x: case.body_data(x))
_fe_matrices = eqx.filter_jit(lambda case, x: case.fe_matrices(x))


def _align(phi, phi_ref, m):
    """`Phi Q` with `Q` the orthogonal matrix closest to `Phi^T M Phi_ref` (signs, rotations)."""
    u, _, vt = np.linalg.svd(np.asarray(phi.T @ (m @ phi_ref)))
    return phi @ jnp.asarray(u @ vt)


def _invariant(case, x):
    """A scalar of the body data invariant under `Phi -> Phi Q`, touching every field with modes."""
    data = case.body_data(x)
    basis = case.modes(x)
    g = data.coupling
    return (
        jnp.trace(data.modal_stiffness) * 1e-7
        + jnp.sum(data.inertia_q**2) * 1e2
        + jnp.sum(data.coupling_0**2) * 1e2
        + jnp.trace(g @ g.T) * 1e-2
        + jnp.sum(data.modal_moment**2)
        + jnp.sum(data.marker_modes**2) * 1e-2
        + jnp.sum(basis.eigenvalues) * 1e-8
    )


_invariant_grad = eqx.filter_jit(jax.grad(_invariant, argnums=1))


# --- building blocks ----------------------------------------------------------------------------


def test_element_operator_and_scipy_matrices_match_dense_assembly():
    mesh = RodMesh(10, 4)
    rng = np.random.default_rng(0)
    youngs, rho = rng.uniform(1.0, 2.0, mesh.n_elements), rng.uniform(1.0, 2.0, mesh.n_elements)
    k_dense = np.asarray(ffr_jax.stiffness_matrix(mesh, jnp.asarray(youngs)))
    m_dense = np.asarray(ffr_jax.mass_matrix(mesh, jnp.asarray(rho)))
    k_op, m_op = sparse_stiffness_matrix(mesh, jnp.asarray(youngs)), sparse_mass_matrix(mesh, jnp.asarray(rho))
    v = jnp.asarray(rng.normal(size=(mesh.n_dof, 3)))
    assert_close_relative(k_op @ v, k_dense @ v, 1e-13, "K @ V (matrix-free vs dense)")
    assert_close_relative(m_op @ v[:, 0], m_dense @ v[:, 0], 1e-13, "M @ v (matrix-free vs dense)")
    fixed = (0, 1, 7)
    free = np.setdiff1d(np.arange(mesh.n_dof), fixed)
    k_ff, m_ff = scipy_matrices(mesh, youngs, rho, fixed)
    assert_close_relative(k_ff.toarray(), k_dense[np.ix_(free, free)], 1e-14, "SciPy K_ff vs dense")
    assert_close_relative(m_ff.toarray(), m_dense[np.ix_(free, free)], 1e-14, "SciPy M_ff vs dense")
    with pytest.raises(ValueError, match="cannot multiply"):
        _ = k_op @ jnp.ones(mesh.n_dof + 1)


# --- sparse vs dense: modes, body data, gradients ------------------------------------------------


def test_sparse_frequencies_and_body_data_match_dense():
    dense, sparse = _cases()
    x = random_design(dense, 0)
    assert_close_relative(_frequencies(sparse, x), _frequencies(dense, x), PATH_RTOL, "frequencies")
    k, m = _fe_matrices(dense, x)
    phi_dense = _modes(dense, x).modes
    phi_sparse = _align(_modes(sparse, x).modes, phi_dense, m)
    expected = _body_data(dense, x)
    aligned = eqx.filter_jit(ffr_jax.flexible_body_data)(dense.mesh, m, k, phi_sparse, dense.marker_nodes)
    from_sparse = _body_data(sparse, x)
    for name in ("mass", "first_moment", "inertia"):
        assert_close_relative(getattr(from_sparse, name), getattr(expected, name), 1e-13, name)
    for name in ("modal_moment", "inertia_q", "modal_mass", "coupling_0", "coupling", "modal_stiffness",
                 "marker_modes"):
        assert_close_relative(getattr(aligned, name), getattr(expected, name), PATH_RTOL, name)


def test_sparse_body_data_gradient_matches_dense():
    dense, sparse = _cases()
    x = random_design(dense, 1)
    g_dense = _invariant_grad(dense, x)
    g_sparse = _invariant_grad(sparse, x)
    assert_close_relative(g_sparse, g_dense, GRAD_RTOL, "gradient of a span-invariant body-data scalar")


@pytest.mark.parametrize("seed", [2, 3])
def test_sparse_eigen_derivative_matches_finite_differences(seed):
    _, sparse = _cases()
    x = random_design(sparse, seed)
    v = jnp.asarray(np.random.default_rng(seed).normal(size=x.shape))
    v = v / jnp.linalg.norm(v)
    step = 1e-4

    @jax.jit
    def functionals(x):
        return jnp.stack([_invariant(sparse, x), jnp.sum(sparse.modes(x).eigenvalues * jnp.arange(1.0, 7.0))])

    fd = (functionals(x + step * v) - functionals(x - step * v)) / (2 * step)
    _, pullback = eqx.filter_vjp(functionals, x)
    for i, name in enumerate(("span-invariant body-data scalar", "weighted eigenvalue sum")):
        (g,) = pullback(jnp.zeros(2).at[i].set(1.0))
        assert_close_relative(g @ v, fd[i], FD_RTOL, f"{name}: VJP . v vs central differences")


def _crossing_design(case):
    """A row-wise design (inner rows at density `s`, outer rows solid) where retained modes 3 and 4 cross.

    The design is symmetric about the rod's axis, so modes symmetric and antisymmetric about it
    (axial and bending) may cross exactly; on the 20 x 4 rod modes 3 and 4 do near `s = 0.28`
    (relative gap 0.35 at `s = 0.2`, 0.32 at `s = 0.4`). A bounded scalar minimisation of the
    relative gap on the host finds the crossing to about 1e-9.

    **Returns:** `(x, relative_gap)`.
    """
    mesh, design = case.mesh, case.design

    def design_at(s):
        rows = np.ones(mesh.ny)
        rows[1:-1] = s
        return np.repeat(rows, mesh.nx - 2)

    def relative_gap(s):
        xe = design.element_densities(jnp.asarray(design_at(s)))
        youngs, rho = np.asarray(design.material.youngs(xe)), np.asarray(design.material.densities(xe))
        k, m = scipy_matrices(mesh, youngs, rho, case.fixed_dofs)
        lam = scipy.linalg.eigh(k.toarray(), m.toarray(), eigvals_only=True, subset_by_index=[0, 3])
        return (lam[3] - lam[2]) / lam[2]

    res = scipy.optimize.minimize_scalar(relative_gap, bounds=(0.2, 0.4), method="bounded", options={"xatol": 1e-12})
    return jnp.asarray(design_at(res.x)), res.fun


def test_sparse_derivative_stable_at_crossing_retained_eigenvalues():
    dense, sparse = _cases()
    x, gap = _crossing_design(dense)
    assert gap < 1e-7, f"no crossing found (relative gap {gap:.1e})"
    g_sparse = _invariant_grad(sparse, x)
    g_dense = _invariant_grad(dense, x)
    assert np.all(np.isfinite(np.asarray(g_sparse))), "sparse gradient at the crossing is finite"
    assert_close_relative(g_sparse, g_dense, 1e-6, "sparse vs dense gradient at crossing eigenvalues")


@pytest.fixture(scope="module")
def scene_gradient():
    """`(psi, dpsi/dp)` of a scene by the adjoint method, compiled once for both paths."""
    dense, _ = _cases(12, 2, 4, 0.2)
    return eqx.filter_jit(lambda scene: ffr_jax.value_and_grad_scene(dense, scene, method="adjoint"))


@eqx.filter_jit
def _scene_pullback(case, x, g_scene):
    _, pullback = eqx.filter_vjp(case.scene, x)
    return pullback(g_scene)[0]


@pytest.mark.slow  # one adjoint compile (about a minute here); benchmarks/bench_scale.py also compares
def test_sparse_psi_and_gradient_match_dense(scene_gradient):
    dense, sparse = _cases(12, 2, 4, 0.2)
    x = random_design(dense, 4)
    results = {}
    for case in (dense, sparse):
        # value_and_grad(case, x) in two parts, so that the dynamics compile once for both paths.
        scene = eqx.filter_jit(lambda case, x: case.scene(x))(case, x)
        psi, g_scene = scene_gradient(scene)
        results[case.fe_path] = (psi, _scene_pullback(case, x, g_scene))
    assert_close_relative(results["sparse"][0], results["dense"][0], PATH_RTOL, "psi")
    assert_close_relative(results["sparse"][1], results["dense"][1], GRAD_RTOL, "adjoint gradient of psi")


# --- path choice, large meshes, bad input --------------------------------------------------------


def test_fe_path_is_chosen_by_size_and_can_be_overridden():
    assert resolve_fe_path("auto", RodMesh(20, 4)) == "dense", "small meshes stay dense"
    assert resolve_fe_path("auto", RodMesh(100, 6)) == "sparse", "the reference rod (1,414 dofs) is sparse"
    big = RodMesh(400, 6)
    assert big.n_dof > SPARSE_MIN_DOF and resolve_fe_path("auto", big) == "sparse"
    assert resolve_fe_path("dense", big) == "dense" and resolve_fe_path("sparse", RodMesh(4, 2)) == "sparse"
    dense, sparse = _cases()
    assert not ffr_jax.cases.slider_crank(20, 4, 6, 0.2).sparse_fe
    assert sparse.sparse_fe and not dense.sparse_fe
    k, m = sparse.fe_matrices(sparse.initial_design(0.5))
    assert isinstance(k, ffr_jax.ElementOperator) and isinstance(m, ffr_jax.ElementOperator)
    with pytest.raises(ValueError, match="fe_path must be one of"):
        ffr_jax.cases.slider_crank(20, 4, 6, 0.2, fe_path="banded")


def test_sparse_path_refuses_forward_mode_and_too_many_modes():
    _, sparse = _cases()
    x = sparse.initial_design(0.5)
    with pytest.raises(TypeError, match="forward-mode"):
        jax.jvp(sparse.frequencies, (x,), (x,))
    k, m = sparse.fe_matrices(x)
    with pytest.raises(ValueError, match="n_modes=500"):
        sparse_hinged_modes(k, m, sparse.fixed_dofs, 500)


def test_largest_mesh_layout_without_dense_matrices():
    """1000 x 100 elements (99,800 design variables, 202,202 dofs): layout and matrix-free products."""
    mesh = RodMesh(1000, 100)
    design = ffr_jax.RodDesign(mesh, ffr_jax.SIMP())
    assert design.n_design == 99_800 and mesh.n_dof == 202_202
    x = design.check(design.initial_design(0.5))
    xe = design.element_densities(x)
    assert xe.shape == (mesh.n_elements,)
    m = sparse_mass_matrix(mesh, design.material.densities(xe))
    e_x = jnp.zeros(mesh.n_dof).at[0::2].set(1.0)
    mass = e_x @ (m @ e_x)
    expected = float(jnp.sum(design.material.densities(xe))) * mesh.dx * mesh.dy * mesh.thickness
    assert_close_relative(mass, expected, 1e-12, "total mass of the 1000 x 100 rod")
    c = mesh.node_coordinates()
    np.testing.assert_allclose(c[mesh.node_a], [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(c[mesh.node_b], [1.0, 0.0], atol=1e-12)


@pytest.mark.slow
def test_largest_mesh_case_frequencies():
    case = ffr_jax.cases.slider_crank(1000, 100, 6, 0.2)
    assert case.sparse_fe and case.n_design == 99_800
    f = np.asarray(case.frequencies(case.initial_design(0.5)))
    reference = np.array([32.552, 128.09, 280.89, 291.47, 483.06, 726.15])
    # A converged mesh of the same rod: within a few per cent of the 100 x 6 reference mesh.
    assert np.all(np.abs(f - reference) / reference < 0.1), f


# --- batches and sharding -------------------------------------------------------------------------


def test_vmap_batch_equals_loop_on_sparse_path():
    _, sparse = _cases()
    xs = jnp.stack([random_design(sparse, s) for s in (5, 6, 7)])
    batched = jax.jit(jax.vmap(sparse.frequencies))(xs)
    for b in range(xs.shape[0]):
        assert_close_relative(batched[b], _frequencies(sparse, xs[b]), 1e-12, f"vmap frequencies, design {b}")


_SHARDED_SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    import ffr_jax
    assert len(jax.devices()) == 2, jax.devices()
    rng = np.random.default_rng(0)
    for fe_path, nx, ny in (("dense", 12, 2), ("sparse", 20, 4)):
        case = ffr_jax.cases.slider_crank(nx, ny, 4, 0.2, fe_path=fe_path)

        def f(x):
            gradient = jax.grad(lambda x: jnp.trace(case.body_data(x).modal_stiffness))(x)
            return case.frequencies(x), case.body_data(x).mass, gradient

        one = jax.jit(f)
        sharded = ffr_jax.sharded_map(f)
        for batch in (3,):  # padded to a multiple of the device count, then split over both devices
            xs = jnp.asarray(rng.uniform(0.2, 0.95, (batch, case.n_design)))
            out = sharded(xs)
            assert all(o.shape[0] == batch for o in out)
            for b in range(batch):
                for name, got, want in zip(("frequencies", "mass", "gradient"), out, one(xs[b])):
                    err = np.max(np.abs(np.asarray(got[b]) - np.asarray(want))) / np.max(np.abs(np.asarray(want)))
                    assert err < 1e-10, (fe_path, batch, b, name, err)
    print("SHARDED OK")
    """
)


def test_sharded_batch_equals_loop_over_designs():
    """On two forced host devices, `sharded_map` equals a loop of single-design calls, both FE paths."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    result = subprocess.run([sys.executable, "-c", _SHARDED_SCRIPT], env=env, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0 and "SHARDED OK" in result.stdout, result.stdout + result.stderr
