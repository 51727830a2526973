"""The sparse modal solution of a supported solid part (issue 27): `LanczosModes` in the solid design chain.

A solid part with supports takes the planar chain's modal solvers on its interior problem (`SolidReductionLayout`):
dense `DenseModes`, sparse `LanczosModes` (host shift-invert Lanczos in a `jax.custom_vjp`, the derivative by
complement solves) or `AutoModes` (Lanczos above 1,000 dofs). Checked on small H8 rods: the eigenpairs and the body
data's reverse-mode derivative of both solvers agree, the Lanczos derivative equals central differences, also where
two retained eigenvalues coincide (a square cross-section: bending in y and z), and the choice and bad supports.

Tolerances (see tests/test_design_modes.py for the argument at length):
- The dense solution's eigenvalues carry an absolute error up to `n eps lam_max` (backward-stable Cholesky
  reduction and symmetric eigensolver; Golub & Van Loan 8.4, 8.7); shift-invert Lanczos is far more accurate on the
  lowest ones. So eigenvalues agree to `2 n eps lam_max`, and the retained span (Davis–Kahan: residual over the gap
  between the last retained and the first discarded eigenvalue) to `span_rtol = 2 n eps lam_max / gap` times the
  M-norm to max-norm conversion `sqrt(cond M_II)`; span invariants and their derivatives (smooth functions of the
  span and the eigenvalues) to the same relative order.
- Central differences of the Lanczos path, five points, step `h = 2e-3` on densities ~0.5: truncation
  `h^4 f^(5) / 30 ~ 1e-11` relative for derivatives of order one in the densities; round-off
  `eps |f| / h ~ 1e-13`, the Lanczos pairs being relative-accurate: `FD_RTOL = 1e-6` bounds both with a wide margin;
  a missing term of the derivative (a mass or a rotation term) shows at the percent level.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from helpers import assert_close_relative

import ffr_jax as fj
from ffr_jax._design.solid_assembly import solid_csc_matrices
from ffr_jax._design.solid_designed_body import SolidDesignedBody
from ffr_jax._design.solid_layout import solid_reduction_layout

EPS = np.finfo(float).eps
FD_RTOL, FD_STEP = 1e-6, 2e-3
N_MODES = 4


def _rod(nx, ny, nz, height, thickness, solver, faces=False, free=False):
    """A 1 m rod of `nx x ny x nz` H8 centred on the x-axis. Supports: the node line through the thickness at A
    (`x = 0, y = 0`) in x, y, z and at B (`x = 1`) in y, z (`faces=False`, the frame of `fj.cases.solid_rod`), or the
    whole end faces (`faces=True`: symmetric under the quarter turn about x when `ny = nz` and `height = thickness`);
    markers those node sets; `free=True`: nothing held (free-free modes)."""
    grid = fj.box_grid(nx, ny, nz, 1.0, height, thickness)
    nodes = grid.nodes - np.array([0.0, height / 2, thickness / 2])
    mesh = fj.SolidMesh(nodes, grid.elements)
    line = np.ones(mesh.n_nodes, bool) if faces else np.abs(nodes[:, 1]) < 1e-12
    a = tuple(int(n) for n in np.flatnonzero(line & (np.abs(nodes[:, 0]) < 1e-12)))
    b = tuple(int(n) for n in np.flatnonzero(line & (np.abs(nodes[:, 0] - 1.0) < 1e-12)))
    fixed = tuple(sorted([3 * n + d for n in a for d in range(3)] + [3 * n + d for n in b for d in (1, 2)]))
    model = fj.SolidFEModel(mesh, fj.H8(), 0.3)
    return SolidDesignedBody(model, fj.SolidDesignDomain(mesh), fj.SIMP(), N_MODES, () if free else fixed, (a, b),
                             solver)


def _design(body, seed):
    return body.initial_design(0.5) + 0.2 * jnp.sin(1.7 * jnp.arange(body.n_design, dtype=float) + seed)


def _invariants(body, x):
    """A scalar of the body data invariant under `Phi -> Phi Q` (Q orthogonal): mass, moments, `sum lam`, and sums
    of squares over the modes; each term of order 1."""
    d = body.body_data(x)
    return (d.mass + jnp.trace(d.second_moment) * 100 + jnp.trace(d.modal_stiffness) / 1e6
            + jnp.sum(d.modal_moment ** 2) + jnp.sum(d.marker_modes ** 2) + jnp.sum(d.marker_rotations ** 2) * 1e-3)


# Compiled once per body (the mesh is static): eager evaluation would compile every primitive on its own.
_value = jax.jit(_invariants)
_value_and_grad = jax.jit(jax.value_and_grad(_invariants, argnums=1))
_eigenpairs = jax.jit(lambda body, x: body.eigenpairs(x))


def _spectrum(body, x):
    """All eigenvalues of the interior pencil (LAPACK), and `sqrt(cond M_II)`."""
    youngs, densities = (np.asarray(v) for v in body.element_values(x))
    layout = body.layout
    k, m = layout.csc_matrices(youngs, densities, np.asarray(body.model.unit_stiffness),
                               np.asarray(body.model.unit_mass))
    k, m = k.toarray(), m.toarray()
    return scipy.linalg.eigh(k, m, eigvals_only=True), np.sqrt(np.linalg.cond(m)), m, layout.interior


def _five_point(f, x, d, h=FD_STEP):
    return float(-f(x + 2 * h * d) + 8 * f(x + h * d) - 8 * f(x - h * d) + f(x - 2 * h * d)) / (12 * h)


def _grad(body, x):
    return _value_and_grad(body, x)[1]


@pytest.fixture(scope="module")
def pair():
    dense, lanczos = _rod(10, 2, 2, 0.06, 0.02, fj.DenseModes()), _rod(10, 2, 2, 0.06, 0.02, fj.LanczosModes())
    return dense, lanczos, _design(dense, 0.0)


@pytest.mark.slow
def test_dense_and_lanczos_eigenpairs_and_body_data_derivative_agree(pair):
    dense, lanczos, x = pair
    lam_all, conversion, m, interior = _spectrum(dense, x)
    accuracy = interior.size * EPS * lam_all[-1]
    (lam_d, phi_d), (lam_l, phi_l) = _eigenpairs(dense, x), _eigenpairs(lanczos, x)
    np.testing.assert_allclose(lam_l, lam_d, rtol=0, atol=2 * accuracy, err_msg="eigenvalues")
    np.testing.assert_allclose(lam_l, lam_all[:N_MODES], rtol=0, atol=2 * accuracy, err_msg="lowest eigenvalues")
    span_rtol = 2 * accuracy / (lam_all[N_MODES] - lam_all[N_MODES - 1]) * conversion

    def projector(phi):
        phi = np.asarray(phi)[interior]
        return phi @ (m @ phi).T

    assert_close_relative(projector(phi_l), projector(phi_d), span_rtol, "M-orthogonal projector onto the span")
    value_d, g_d = _value_and_grad(dense, x)
    value, g_l = _value_and_grad(lanczos, x)
    assert_close_relative(float(value), float(value_d), span_rtol, "body-data invariants")
    assert_close_relative(g_l, g_d, span_rtol, "body-data VJP (Lanczos vs dense)")


@pytest.mark.slow
def test_lanczos_body_data_derivative_matches_central_differences(pair):
    _, lanczos, x = pair
    grad = _grad(lanczos, x)
    direction = jnp.asarray(np.random.default_rng(1).uniform(-1.0, 1.0, lanczos.n_design))
    for name, d in (("random direction", direction),
                    ("largest entry", jnp.zeros(lanczos.n_design).at[int(jnp.argmax(jnp.abs(grad)))].set(1.0))):
        fd = _five_point(lambda y: _value(lanczos, y), x, d)
        np.testing.assert_allclose(float(grad @ d), fd, rtol=FD_RTOL, err_msg=f"Lanczos VJP vs FD: {name}")


@pytest.mark.slow
def test_derivative_finite_and_exact_at_coincident_retained_eigenvalues():
    """A square cross-section held on both end faces is symmetric under the quarter turn about its axis, so at a
    uniform design bending in y and in z have one eigenvalue (a double retained pair, equal to round-off): the
    derivative of span invariants stays finite and equals the dense solver's and central differences (only the
    gaps to the discarded eigenvalues enter; jax's generic `eigh` rule would divide by the zero gap)."""
    lanczos = _rod(8, 2, 2, 0.04, 0.04, fj.LanczosModes(), faces=True)
    dense = _rod(8, 2, 2, 0.04, 0.04, fj.DenseModes(), faces=True)
    x = lanczos.initial_design(0.6)
    lam_all, conversion, _, interior = _spectrum(lanczos, x)
    assert abs(lam_all[1] - lam_all[0]) <= 1e-10 * lam_all[0], f"no double pair: {lam_all[:3]}"
    grad = _grad(lanczos, x)
    assert np.all(np.isfinite(np.asarray(grad))), "finite derivative at the double eigenvalue"
    span_rtol = 2 * interior.size * EPS * lam_all[-1] / (lam_all[N_MODES] - lam_all[N_MODES - 1]) * conversion
    assert_close_relative(grad, _grad(dense, x), span_rtol, "VJP at the double pair")
    direction = jnp.asarray(np.random.default_rng(2).uniform(-1.0, 1.0, lanczos.n_design))
    fd = _five_point(lambda y: _value(lanczos, y), x, direction)
    np.testing.assert_allclose(float(grad @ direction), fd, rtol=FD_RTOL, err_msg="VJP vs FD at the double pair")


def test_auto_modes_choose_by_size_and_bad_supports():
    small, large = _rod(10, 2, 2, 0.06, 0.02, fj.AutoModes()), _rod(40, 2, 4, 0.06, 0.02, fj.AutoModes())
    assert small.model.n_dof <= 1000 < large.model.n_dof
    assert isinstance(fj.AutoModes().choose(small.model), fj.DenseModes)
    assert isinstance(fj.AutoModes().choose(large.model), fj.LanczosModes)
    body = _rod(4, 2, 2, 0.06, 0.02, fj.LanczosModes())
    with pytest.raises(ValueError, match="do not remove the rigid-body motions"):
        solid_reduction_layout(body.mesh, body.fixed_dofs[:3])  # A held alone: the turns about A's line are free


@pytest.mark.slow
def test_free_part_lanczos_equals_dense():
    """A free part (no supports): Lanczos computes the six rigid-body modes with a shift below zero and drops them;
    its eigenpairs and body-data VJP equal `free_modes_dense`'s (which deflates the rigid modes to `sigma` above the
    retained range) to the dense solution's accuracy (module docstring), and its VJP equals central differences
    (the rigid-body part of the derivative, `-R R^T dM Phi`, matters: without it the mass terms are off)."""
    dense = _rod(10, 2, 2, 0.06, 0.02, fj.DenseModes(), free=True)
    lanczos = _rod(10, 2, 2, 0.06, 0.02, fj.LanczosModes(), free=True)
    x = _design(dense, 0.5)
    (lam_d, phi_d), (lam_l, phi_l) = _eigenpairs(dense, x), _eigenpairs(lanczos, x)
    youngs, densities = (np.asarray(v) for v in dense.element_values(x))
    k, m = (a.toarray() for a in solid_csc_matrices(dense.model, youngs, densities))
    lam_all = scipy.linalg.eigh(k, m, eigvals_only=True)  # six rigid ones (zero to round-off), then the elastic ones
    accuracy = k.shape[0] * EPS * lam_all[-1]
    np.testing.assert_allclose(lam_l, lam_d, rtol=0, atol=2 * accuracy, err_msg="free-free eigenvalues")
    span_rtol = 2 * accuracy / (lam_all[6 + N_MODES] - lam_all[5 + N_MODES]) * np.sqrt(np.linalg.cond(m))
    assert_close_relative(np.asarray(phi_l) @ (m @ np.asarray(phi_l)).T, np.asarray(phi_d) @ (m @ np.asarray(phi_d)).T,
                          span_rtol, "free-free projector")
    value_d, g_d = _value_and_grad(dense, x)
    value, g_l = _value_and_grad(lanczos, x)
    assert_close_relative(float(value), float(value_d), span_rtol, "free-free body-data invariants")
    assert_close_relative(g_l, g_d, span_rtol, "free-free body-data VJP (Lanczos vs dense)")
    direction = jnp.asarray(np.random.default_rng(3).uniform(-1.0, 1.0, lanczos.n_design))
    fd = _five_point(lambda y: _value(lanczos, y), x, direction)
    np.testing.assert_allclose(float(g_l @ direction), fd, rtol=FD_RTOL, err_msg="free-free Lanczos VJP vs FD")
