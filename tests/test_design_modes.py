"""Modal bases on a distorted mesh: eigen and static modes, dense vs Lanczos, derivatives, crossings.

Modes are compared only through quantities that depend on the span of the basis (projectors,
eigenvalues, traces of `M_qq^-1 K_qq`, ...), except the static modes, which are unique
solutions of linear systems and are compared entry by entry. With static modes the basis is not
M-orthonormal, so the invariants use `M_qq^-1` where an orthonormal basis would not need it:
under `Phi -> Phi T` (any invertible `T`) `S1 M_qq^-1 S1^T`, `j1^T M_qq^-1 j1`,
`tr(M_qq^-1 K_qq)`, `tr(M_qq^-1 G M_qq^-1 G^T)` and `Phi M_qq^-1 Phi^T` are unchanged.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from helpers import assert_close_relative

import ffr_jax._design as fd

# Dense (LAPACK) and Lanczos (ARPACK + SuperLU) solve the same problems by different algorithms,
# each to about machine precision times the condition of the quantity (eigenvalue ratio ~1e4 here).
PATH_RTOL = 1e-9
# Lanczos derivatives: the complement conjugate-gradient solves stop at a relative residual of 1e-12,
# amplified by the condition number lam_{n+1} / (lam_{n+1} - lam_n) (< 10 here).
GRAD_RTOL = 1e-8
# Five-point finite differences with step 2e-3: truncation (h^4 ~ 1e-11 times the 5th derivative)
# and round-off (eps * lam_max / lam_1 / h ~ 1e-9) both far below 1e-6.
FD_RTOL = 1e-6
FD_STEP = 2e-3
NX, NY, N_MODES = 12, 4, 4


def _distorted_mesh():
    """A 12 x 4 grid over 0.6 x 0.1 with the interior nodes moved by up to 25 % of an element."""
    mesh = fd.structured_grid(NX, NY, 0.6, 0.1)
    nodes = np.array(mesh.nodes)
    i, j = np.divmod(np.arange(mesh.n_nodes), NY + 1)
    inner = (i > 0) & (i < NX) & (j > 0) & (j < NY)
    shift = np.random.default_rng(0).uniform(-0.25, 0.25, (mesh.n_nodes, 2)) * [0.6 / NX, 0.1 / NY]
    nodes[inner] += shift[inner]
    return fd.QuadMesh(nodes, mesh.elements, orientation="refuse")


def _node(i, j):
    return i * (NY + 1) + j


def _reductions(solver):
    """The paper's hinged–hinged basis, and a clamped–free Craig–Bampton basis with two interfaces."""
    left = [_node(0, j) for j in range(NY + 1)]
    right = [_node(NX, j) for j in range(NY + 1)]
    return {
        "hinged": fd.ModalReduction(N_MODES, fd.HingedHinged(_node(0, NY // 2), _node(NX, NY // 2)), solver=solver),
        "craig-bampton": fd.ModalReduction(
            N_MODES, fd.Clamped(left),
            interfaces=(fd.Interface(right, rigid=True), fd.Interface([_node(NX // 2, NY)])), solver=solver),
    }


def _body(kind, solver, element=fd.QM6()):
    mesh = _distorted_mesh()
    column = np.arange(mesh.n_elements) % NX
    domain = fd.DesignDomain.from_masks(mesh, solid=(column == 0) | (column == NX - 1))
    model = fd.FEModel(mesh, element, 0.01, 0.3)
    markers = (_node(0, NY // 2), tuple(_node(NX, j) for j in range(NY + 1)))
    return fd.DesignedBody(model, domain, fd.SIMP(), _reductions(solver)[kind], markers)


def _design(body, seed):
    return jnp.asarray(np.random.default_rng(seed).uniform(0.2, 0.95, body.n_design))


def _invariants(body, x):
    """Span invariants of the basis and its body data, and the static modes contracted."""
    basis = body.modes(x)
    k, m = body.matrices(x)
    d = fd.body_data(body.model, k, m, basis.modes, body.markers)
    mq_inv = jnp.linalg.inv(d.modal_mass)
    w = jnp.asarray(np.random.default_rng(42).normal(size=(body.model.n_dof, body.model.n_dof)))
    projector = basis.modes @ mq_inv @ (m @ basis.modes).T
    rows = d.marker_modes.reshape(-1, d.n_modes)
    parts = [
        jnp.sum(basis.eigenvalues) * 1e-8,
        jnp.trace(mq_inv @ d.modal_stiffness) * 1e-8,
        jnp.sum(d.modal_moment @ mq_inv @ d.modal_moment.T),
        d.inertia_q @ mq_inv @ d.inertia_q * 1e2,
        d.coupling_0 @ mq_inv @ d.coupling_0 * 1e2,
        jnp.trace(mq_inv @ d.coupling @ mq_inv @ d.coupling.T),
        jnp.sum(rows @ mq_inv @ rows.T) * 1e2,
        jnp.sum(w * projector),
        d.mass + d.inertia,
    ]
    static = basis.static_modes
    if static.shape[1]:
        v = jnp.asarray(np.random.default_rng(7).normal(size=static.shape))
        parts.append(jnp.sum(v * static))
    return jnp.stack(parts)


NAMES = ("sum of eigenvalues", "tr(Mqq^-1 Kqq)", "S1 Mqq^-1 S1^T", "j1 Mqq^-1 j1", "G0 Mqq^-1 G0",
         "tr(Mqq^-1 G Mqq^-1 G^T)", "marker rows", "projector", "mass + inertia", "static modes")

_invariants_jit = eqx.filter_jit(_invariants)
_body_data_jit = eqx.filter_jit(fd.body_data)
_modes_jit = eqx.filter_jit(lambda body, x: body.modes(x))


@eqx.filter_jit
def _invariants_jacobian(body, x):
    """All gradients at once, by reverse mode (one VJP per invariant, vmapped)."""
    return jax.jacrev(lambda x: _invariants(body, x))(x)


@eqx.filter_jit
def _invariants_jvp(body, x, v):
    return jax.jvp(lambda x: _invariants(body, x), (x,), (v,))[1]


def _five_point(f, x, v, step=FD_STEP):
    return (-f(x + 2 * step * v) + 8 * f(x + step * v) - 8 * f(x - step * v) + f(x - 2 * step * v)) / (12 * step)


def _unit(n, seed):
    v = np.random.default_rng(seed).normal(size=n)
    return jnp.asarray(v / np.linalg.norm(v))


KINDS = ("hinged", "craig-bampton")


# --- the modes solve their problems --------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_basis_solves_the_eigenproblem_and_the_static_problems(kind):
    body = _body(kind, fd.DenseModes())
    x = _design(body, 0)
    basis = _modes_jit(body, x)
    k, m = (a.todense() for a in body.matrices(x))
    layout = body.reduction.layout(body.model.mesh)
    interior, removed = layout.interior, np.asarray(layout.removed)
    phi, psi, lam = basis.eigenmodes, basis.static_modes, basis.eigenvalues
    assert basis.n_static == (0 if kind == "hinged" else 3 + 2)
    assert np.all(np.asarray(phi)[removed] == 0.0), "eigenmodes vanish on held and interface dofs"
    assert_close_relative((k @ phi)[interior], (m @ phi * lam)[interior], PATH_RTOL, "K Phi = M Phi Lambda")
    assert_close_relative(phi.T @ m @ phi, np.eye(N_MODES), PATH_RTOL, "Phi^T M Phi = I")
    # The retained eigenvalues are the lowest of the interior problem.
    all_lam = scipy.linalg.eigh(np.asarray(k)[np.ix_(interior, interior)], np.asarray(m)[np.ix_(interior, interior)],
                                eigvals_only=True)
    np.testing.assert_allclose(lam, all_lam[:N_MODES], rtol=PATH_RTOL, err_msg="lowest eigenvalues")
    if kind == "craig-bampton":
        forces = np.asarray(k @ psi)
        residual = np.abs(forces[interior]).max() / np.abs(forces).max()
        assert residual < PATH_RTOL, f"static modes: interior in equilibrium, |(K Psi)_I| / |K Psi| = {residual:.1e}"
        assert np.all(np.asarray(psi)[list(layout.fixed)] == 0.0), "static modes vanish on the clamped dofs"
        rim = np.asarray(psi).reshape(-1, 2, 5)[[_node(NX, j) for j in range(NY + 1)]]
        rim_xy = body.model.mesh.nodes[[_node(NX, j) for j in range(NY + 1)]]
        for s in range(3):  # the rigid interface moves rigidly: u = a + theta I~ (x - x_c)
            fit = np.linalg.lstsq(np.block([[np.ones((NY + 1, 1)), np.zeros((NY + 1, 1)), -rim_xy[:, 1:]],
                                            [np.zeros((NY + 1, 1)), np.ones((NY + 1, 1)), rim_xy[:, :1]]]),
                                  np.concatenate([rim[:, 0, s], rim[:, 1, s]]), rcond=None)
            assert fit[1].size == 0 or fit[1][0] < 1e-24, f"static mode {s} moves the rigid interface rigidly"


@pytest.mark.parametrize("kind", KINDS)
def test_dense_and_lanczos_agree(kind):
    dense, lanczos = _body(kind, fd.DenseModes()), _body(kind, fd.LanczosModes())
    x = _design(dense, 1)
    a, b = _modes_jit(dense, x), _modes_jit(lanczos, x)
    assert_close_relative(b.eigenvalues, a.eigenvalues, PATH_RTOL, "eigenvalues")
    assert_close_relative(b.static_modes, a.static_modes, PATH_RTOL, "static modes (unique)")
    _, m = dense.matrices(x)
    m = m.todense()

    def projector(phi):
        return phi @ jnp.linalg.solve(phi.T @ m @ phi, (m @ phi).T)

    assert_close_relative(projector(b.modes), projector(a.modes), PATH_RTOL, "M-orthogonal projector onto the span")
    assert_close_relative(_invariants_jit(lanczos, x), _invariants_jit(dense, x), PATH_RTOL, "span invariants")


def test_body_data_is_covariant_under_any_change_of_basis():
    """`Phi -> Phi T` with `T` invertible, not orthogonal: every modal field transforms, nothing assumes
    `Phi^T M Phi = I`; mass, first moment and inertia are the polygon integrals of the mesh."""
    body = _body("craig-bampton", fd.DenseModes())
    x = jnp.full(body.n_design, 1.0)
    basis = _modes_jit(body, x)
    k, m = body.matrices(x)
    t = jnp.asarray(np.eye(9) + 0.3 * np.random.default_rng(3).normal(size=(9, 9)))
    a = _body_data_jit(body.model, k, m, basis.modes, body.markers)
    b = _body_data_jit(body.model, k, m, basis.modes @ t, body.markers)
    for name, expected in (("modal_moment", a.modal_moment @ t), ("inertia_q", t.T @ a.inertia_q),
                           ("modal_mass", t.T @ a.modal_mass @ t), ("coupling_0", t.T @ a.coupling_0),
                           ("coupling", t.T @ a.coupling @ t), ("modal_stiffness", t.T @ a.modal_stiffness @ t),
                           ("marker_modes", a.marker_modes @ t)):
        assert_close_relative(getattr(b, name), expected, 1e-12, name)
    assert_close_relative(a.coupling, -a.coupling.T, 1e-12, "G is skew-symmetric")
    # Exact integrals of a polygonal body of density rho: the consistent mass with 2x2 Gauss
    # integrates 1, x, y, x^2 + y^2 exactly on any bilinear quadrilateral.
    mesh, rho, t_ = body.model.mesh, body.material.density, body.model.thickness
    xy = mesh.element_coordinates()
    x0, y0, x1, y1 = xy[..., 0], xy[..., 1], np.roll(xy[..., 0], -1, 1), np.roll(xy[..., 1], -1, 1)
    cross = x0 * y1 - x1 * y0
    area = cross.sum() / 2
    sx, sy = ((x0 + x1) * cross).sum() / 6, ((y0 + y1) * cross).sum() / 6
    polar = ((x0**2 + x0 * x1 + x1**2 + y0**2 + y0 * y1 + y1**2) * cross).sum() / 12
    np.testing.assert_allclose(a.mass, rho * t_ * area, rtol=1e-12, err_msg="mass")
    assert_close_relative(a.first_moment, rho * t_ * np.array([sx, sy]), 1e-12, "first moment")
    np.testing.assert_allclose(a.inertia, rho * t_ * polar, rtol=1e-12, err_msg="polar inertia")
    rim = [_node(NX, j) for j in range(NY + 1)]
    np.testing.assert_allclose(a.marker_positions[1], mesh.nodes[rim].mean(0), rtol=1e-14)
    # The rigid interface's static modes move its centroid by their translation part: (1, 0), (0, 1), (0, 0).
    np.testing.assert_allclose(a.marker_modes[1][:, N_MODES + 0: N_MODES + 3], np.eye(2, 3), atol=1e-14,
                               err_msg="centroid marker rows of the rigid-interface static modes")


# --- derivatives ---------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_derivatives_dense_jvp_lanczos_vjp_and_finite_differences(kind):
    """Every invariant's derivative along a direction three ways: dense forward mode (the custom JVP
    rule and autodiff of the static solves), Lanczos reverse mode (host sparse solves), and
    five-point finite differences."""
    dense, lanczos = _body(kind, fd.DenseModes()), _body(kind, fd.LanczosModes())
    x = _design(dense, 2)
    v = _unit(dense.n_design, 20)
    tangent = _invariants_jvp(dense, x, v)
    fd_ = _five_point(lambda x: _invariants_jit(dense, x), x, v)
    jacobian = _invariants_jacobian(lanczos, x)
    for i in range(tangent.shape[0]):
        np.testing.assert_allclose(tangent[i], fd_[i], rtol=FD_RTOL, err_msg=f"dense JVP vs FD: {NAMES[i]} ({kind})")
        np.testing.assert_allclose(jacobian[i] @ v, tangent[i], rtol=GRAD_RTOL,
                                   err_msg=f"Lanczos VJP vs dense JVP: {NAMES[i]} ({kind})")


# --- crossing retained eigenvalues -----------------------------------------------------------------


def _rod_body(solver, nx=20, ny=4, n_modes=6):
    domain = fd.rod_domain(nx, ny)
    a, b = fd.rod_joint_nodes(nx, ny)
    model = fd.FEModel(domain.mesh, fd.Q4(), 0.01, 0.3)
    return fd.DesignedBody(model, domain, fd.SIMP(), fd.ModalReduction(n_modes, fd.HingedHinged(a, b), solver=solver),
                           (a, b))


def _crossing_design(body):
    """A row-wise design (outer rows 0.9, inner rows `s`) where retained modes 3 and 4 of the 20 x 4 rod cross.

    The design is symmetric about the rod's axis, so axial and bending modes may cross exactly;
    a bounded scalar minimisation of their relative gap on the host finds `s` to about 1e-9.
    """
    ny, nx = 4, 20

    def design_at(s):
        rows = np.full(ny, 0.9)  # not 1, so that finite differences stay inside [x_min, 1]
        rows[1:-1] = s
        return np.repeat(rows, nx - 2)

    layout = body.reduction.layout(body.model.mesh)
    unit_k, unit_m = np.asarray(body.model.unit_stiffness), np.asarray(body.model.unit_mass)
    element_values = eqx.filter_jit(lambda body, x: body.element_values(x))

    def relative_gap(s):
        youngs, rho = (np.asarray(v) for v in element_values(body, jnp.asarray(design_at(s))))
        k, m = fd.csc_matrices(body.model.mesh, youngs, rho, unit_k, unit_m, layout.removed)
        lam = scipy.linalg.eigh(k.toarray(), m.toarray(), eigvals_only=True, subset_by_index=[0, 3])
        return (lam[3] - lam[2]) / lam[2]

    res = scipy.optimize.minimize_scalar(relative_gap, bounds=(0.2, 0.4), method="bounded", options={"xatol": 1e-12})
    return jnp.asarray(design_at(res.x)), res.fun


def test_lanczos_derivative_stable_at_crossing_retained_eigenvalues():
    lanczos = _rod_body(fd.LanczosModes())
    x, gap = _crossing_design(lanczos)
    assert gap < 1e-7, f"no crossing found (relative gap {gap:.1e})"
    v = _unit(lanczos.n_design, 50)
    fd_ = _five_point(lambda x: _invariants_jit(lanczos, x), x, v, step=1e-4)
    jacobian = _invariants_jacobian(lanczos, x)
    assert np.all(np.isfinite(np.asarray(jacobian))), "finite gradients at the crossing"
    for i in range(fd_.shape[0]):
        np.testing.assert_allclose(jacobian[i] @ v, fd_[i], rtol=FD_RTOL, err_msg=f"Lanczos VJP vs FD at crossing: {NAMES[i]}")


def _pencil_with_spectrum(eigenvalues, seed):
    """`(K, M)` with prescribed generalized eigenvalues: `M` random SPD, `V = L^-T Q`, `K = M V diag(lam) V^T M`."""
    n = len(eigenvalues)
    rng = np.random.default_rng(seed)
    b = rng.normal(size=(n, n))
    m = b @ b.T + n * np.eye(n)
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    v = np.linalg.solve(np.linalg.cholesky(m).T, q)
    k = m @ v @ np.diag(eigenvalues) @ v.T @ m
    return jnp.asarray(0.5 * (k + k.T)), jnp.asarray(m)


@pytest.mark.parametrize("spectrum", [[1.0, 2.0, 3.0, 3.0, 5.0, 6.0, 7.0, 8.0], [0.5, 3.0, 3.0, 3.0, 4.0, 6.0, 6.0, 9.0]],
                         ids=["double", "triple"])
def test_dense_rule_at_coincident_retained_eigenvalues(spectrum):
    """`retained_eigenpairs` (the dense solver's rule): span invariants along a path through coincident
    retained eigenvalues have finite forward and reverse derivatives equal to finite differences."""
    n_modes = 4
    k, m = _pencil_with_spectrum(spectrum, 0)
    rng = np.random.default_rng(1)
    dk, dm = (jnp.asarray(0.5 * (a + a.T)) for a in (rng.normal(size=(8, 8)), 0.1 * rng.normal(size=(8, 8))))
    w = jnp.asarray(rng.normal(size=(8, 8)))

    @jax.jit
    def along_path(t):
        kt, mt = k + t * dk, m + t * dm
        lam, phi = fd.retained_eigenpairs(kt, mt, n_modes)
        return jnp.stack([jnp.sum(lam), jnp.trace(phi.T @ kt @ phi), jnp.sum(w * (phi @ phi.T @ mt))])

    t0 = jnp.array(0.0)
    _, forward = jax.jvp(along_path, (t0,), (jnp.array(1.0),))
    reverse = jax.jacrev(along_path)(t0)
    fd_ = _five_point(along_path, t0, jnp.array(1.0), step=1e-4)
    np.testing.assert_allclose(forward, fd_, rtol=FD_RTOL, err_msg="JVP vs FD (eigenvalue sum, trace, projector)")
    np.testing.assert_allclose(reverse, forward, rtol=1e-12, err_msg="reverse vs forward mode")


def test_subspace_derivative_gauge():
    """The documented gauge of `retained_eigenpairs`: `Phi^T M dPhi` is symmetric, hence `= -1/2 Phi^T dM Phi`
    (the rod's interior pencil along a random design direction; exact arithmetic up to round-off)."""
    body = _rod_body(fd.DenseModes(), nx=12, ny=2, n_modes=4)
    x = _design(body, 5)
    v = _unit(body.n_design, 500)
    (k, m), (dk, dm) = jax.jvp(lambda x: tuple(a.todense() for a in body.matrices(x)), (x,), (v,))
    interior = body.reduction.layout(body.mesh).interior
    ix = np.ix_(interior, interior)
    (_, phi), (_, dphi) = jax.jvp(lambda a, b: fd.retained_eigenpairs(a, b, 4), (k[ix], m[ix]), (dk[ix], dm[ix]))
    assert_close_relative(phi.T @ m[ix] @ dphi, -0.5 * phi.T @ dm[ix] @ phi, 1e-10, "Phi^T M dPhi = -1/2 Phi^T dM Phi")


# --- bad input -----------------------------------------------------------------------------------


def test_reference_conditions_and_interfaces_are_checked():
    mesh = _distorted_mesh()
    model = fd.FEModel(mesh, fd.Q4(), 0.01)
    domain = fd.DesignDomain(mesh)

    def body(reduction, markers=(0,)):
        return fd.DesignedBody(model, domain, fd.SIMP(), reduction, markers)

    with pytest.raises(ValueError, match=r"Interface nodes: nodes 9999 are not in the mesh"):
        body(fd.ModalReduction(2, fd.Clamped([0, 1]), interfaces=(fd.Interface([3, 9999]),)))
    with pytest.raises(ValueError, match="marker 1: nodes 70 are not in the mesh"):
        body(fd.ModalReduction(2, fd.Clamped([0, 1])), markers=(0, 70))
    with pytest.raises(ValueError, match="along the x- or y-axis"):
        body(fd.ModalReduction(2, fd.HingedHinged(0, _node(NX, NY))))
    with pytest.raises(ValueError, match="do not remove the rigid-body motions .*rank 2"):
        body(fd.ModalReduction(2, fd.FixedDofs([0, 1])))
    with pytest.raises(ValueError, match="rigid Interface may not contain held"):
        body(fd.ModalReduction(2, fd.Clamped([0, 1]), interfaces=(fd.Interface([1, 2], rigid=True),)))
    with pytest.raises(ValueError, match="Interfaces 0 and 1 share nodes 3"):
        body(fd.ModalReduction(2, fd.Clamped([0, 1]), interfaces=(fd.Interface([3, 4]), fd.Interface([3]))))
    with pytest.raises(ValueError, match="n_modes must be a positive int"):
        fd.ModalReduction(0, fd.Clamped([0, 1]))
    with pytest.raises(TypeError, match="forward-mode"):
        lanczos = _body("hinged", fd.LanczosModes())
        jax.jvp(lanczos.frequencies, (_design(lanczos, 0),), (_design(lanczos, 1),))


def test_auto_modes_choose_by_size():
    small, large = _body("hinged", fd.AutoModes()), _rod_body(fd.AutoModes(), nx=100, ny=6)
    assert isinstance(small.reduction.solver.choose(small.model), fd.DenseModes)
    assert isinstance(large.reduction.solver.choose(large.model), fd.LanczosModes), "the reference rod is sparse"


def test_lanczos_batch_of_designs_under_vmap():
    body = _body("craig-bampton", fd.LanczosModes())
    xs = jnp.stack([_design(body, s) for s in (5, 6)])
    batched = eqx.filter_jit(eqx.filter_vmap(lambda x: body.frequencies(x)))(xs)
    for b in range(2):
        assert_close_relative(batched[b], _modes_jit(body, xs[b]).frequencies, 1e-12, f"vmap frequencies, design {b}")
