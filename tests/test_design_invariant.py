"""THE INVARIANT: the reference rod's numbers do not move, whichever way its mesh is given.

1. The reference rod (100 x 6 Q4 elements, 588 densities, hinged–hinged, 6 modes, Lanczos) has the
   frequencies quoted in REFERENCE_CASE §2.
2. The reference rod built on the structured grid and read as an UNSTRUCTURED mesh (nodes and
   elements shuffled, each element's node list rotated, written and re-read through meshio) has
   the same K, M, frequencies, span projector of the modes, body data and gradient of a
   span-invariant body-data scalar to 1e-10 (relative to each quantity's size).
3. Through the full case: a small slider–crank whose rod is the unstructured mesh gives the psi and
   the adjoint gradient of the structured one to 1e-10 (the reference case:
   benchmarks/RESULTS.md, "Rod cases before and after the design map", which also compares the
   numbers with those of the FE modules the design map replaced).

Tolerance of 2: the two meshes give the same matrices up to the summation order (1e-15 relative)
and ARPACK starts from different vectors. Eigenvalues move by `phi^T dK phi / phi^T M phi`,
relative 1e-14 times the ratio of element to modal stiffness, and the retained span by that over
the relative gap to the first discarded mode (874 vs 726 Hz); gradients add the complement
solves' residual 1e-12. 1e-10 leaves room for all of it (measured: K, M 1e-15; frequencies
and body data up to 1e-12). Tolerance of 3: body data equal to 1e-12 move psi and the gradient
smoothly by as much while the two adaptive solves accept the same steps; where a step decision
differs, the results differ by the solves' local errors instead, bounded by their tolerances. The
solves run at forward rtol 1e-12 and backward rtol 1e-11 (absolute tolerances far below the
states: psi ~ 3e-7, elastic coordinates ~ 1e-5), so 1e-10 bounds both (at the default backward
rtol 1e-8 the gradients differ by 1.5e-9 of max |grad|; here psi by 3e-13, the gradient by 6e-12).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_close_relative

import ffr_jax as fj
import ffr_jax._design as fd

NX, NY, N_MODES = 100, 6, 6
RTOL = 1e-10
FIELDS = ("mass", "first_moment", "modal_moment", "inertia", "inertia_q", "modal_mass", "coupling_0", "coupling",
          "modal_stiffness", "marker_positions", "marker_modes")
# REFERENCE_CASE §2, to the digits quoted there (a half unit of the last quoted digit).
REFERENCE_FREQUENCIES = [(32.6, 0.05), (128.0, 0.5), (281.0, 0.5), (291.0, 0.5), (483.0, 0.5), (726.0, 0.5)]


def _scalar(data, eigenvalues):
    """A scalar of the body data invariant under `Phi -> Phi Q` (Q orthogonal), touching every modal field."""
    g = data.coupling
    return (jnp.trace(data.modal_stiffness) * 1e-7 + jnp.sum(data.inertia_q**2) * 1e2
            + jnp.sum(data.coupling_0**2) * 1e2 + jnp.trace(g @ g.T) * 1e-2 + jnp.sum(data.modal_moment**2)
            + jnp.sum(data.marker_modes**2) * 1e-2 + jnp.sum(eigenvalues) * 1e-8)


@eqx.filter_jit
def _pipeline(body, x):
    def run(x):
        basis = body.modes(x)
        k, m = body.matrices(x)
        data = fd.body_data(body.model, k, m, basis.modes, body.markers)
        return _scalar(data, basis.eigenvalues), (basis, data)

    (_, (basis, data)), grad = jax.value_and_grad(run, has_aux=True)(x)
    return basis, data, grad


def _shuffled_rod(structured: fd.DesignedBody, directory, seed: int = 1):
    """The rod as an unstructured mesh: permuted nodes and elements, rotated node lists, via meshio.

    **Returns:** `(body, node_of, design_of)`: `node_of[n]` the rod node of new node `n`, and
    `design_of[i]` the rod design index of new design variable `i`.
    """
    domain, mesh = structured.domain, structured.mesh
    rng = np.random.default_rng(seed)
    node_of = rng.permutation(mesh.n_nodes)
    new_index = np.argsort(node_of)
    element_of = rng.permutation(mesh.n_elements)
    shift = rng.integers(0, 4, mesh.n_elements)
    rotated = np.take_along_axis(mesh.elements[element_of], (np.arange(4) + shift[:, None]) % 4, axis=1)
    path = directory / "rod.vtu"
    fd.write_mesh(str(path), fd.QuadMesh(mesh.nodes[node_of], new_index[rotated]))
    read = fd.read_mesh(str(path))
    shuffled = fd.DesignDomain(read, domain.role_array()[element_of])
    old_design_index = np.full(mesh.n_elements, -1)
    old_design_index[np.asarray(domain.design_elements)] = np.arange(domain.n_design)
    design_of = old_design_index[element_of[np.asarray(shuffled.design_elements)]]
    a, b = (int(new_index[n]) for n in structured.markers)
    model = fd.FEModel(read, structured.model.element, structured.model.thickness, structured.model.poisson)
    reduction = fd.ModalReduction(structured.n_modes, fd.HingedHinged(a, b), solver=structured.reduction.solver)
    body = fd.DesignedBody(model, shuffled, structured.material, reduction, (a, b))
    return body, node_of, design_of


@pytest.fixture(scope="module")
def reference():
    body = fj.cases.rod_body(NX, NY, N_MODES, modal_solver=fd.LanczosModes())
    x = jnp.asarray(np.random.default_rng(0).uniform(0.2, 0.95, body.n_design))
    basis, data, grad = _pipeline(body, x)
    youngs, rho = (np.asarray(v) for v in body.element_values(x))
    k, m = fd.csc_matrices(body.mesh, youngs, rho, np.asarray(body.model.unit_stiffness),
                           np.asarray(body.model.unit_mass))
    return dict(body=body, x=x, basis=basis, data=data, grad=grad, k=k, m=m)


def test_reference_rod_frequencies(reference):
    frequencies = eqx.filter_jit(lambda body, x: body.frequencies(x))(reference["body"],
                                                                      reference["body"].initial_design(0.5))
    for n, (f, (quoted, half_digit)) in enumerate(zip(np.asarray(frequencies), REFERENCE_FREQUENCIES), 1):
        assert abs(f - quoted) <= half_digit, f"reference frequency {n}: {f:.4f} Hz, quoted {quoted} Hz"


def test_reference_rod_unstructured_via_meshio(reference, tmp_path):
    body, node_of, design_of = _shuffled_rod(reference["body"], tmp_path)
    assert not np.array_equal(node_of, np.arange(node_of.size)), "the nodes are shuffled"
    dof_of = np.stack([2 * node_of, 2 * node_of + 1], axis=1).ravel()  # rod dof of each new dof
    x_new = reference["x"][design_of]
    basis, data, grad = _pipeline(body, x_new)
    youngs, rho = (np.asarray(v) for v in body.element_values(x_new))
    k, m = fd.csc_matrices(body.mesh, youngs, rho, np.asarray(body.model.unit_stiffness),
                           np.asarray(body.model.unit_mass))
    inverse = np.argsort(dof_of)
    for name, new, old in (("K", k, reference["k"]), ("M", m, reference["m"])):
        assert_close_relative(new.toarray()[np.ix_(inverse, inverse)], old.toarray(), RTOL, f"{name} (rod numbering)")
    old_basis, old_data = reference["basis"], reference["data"]
    assert_close_relative(basis.frequencies, old_basis.frequencies, RTOL, "frequencies")
    m_rod = reference["m"].toarray()
    phi_new = np.asarray(basis.modes)[inverse]  # rod dof order
    phi_old = np.asarray(old_basis.modes)
    assert_close_relative(phi_new @ (m_rod @ phi_new).T, phi_old @ (m_rod @ phi_old).T, RTOL,
                          "M-orthogonal projector onto the retained modes")
    # Body data: align the new modes to the old ones (signs, rotations in clusters), then every field.
    u, _, vt = np.linalg.svd(phi_new.T @ m_rod @ phi_old)
    rot = u @ vt
    aligned = dict(modal_moment=data.modal_moment @ rot, inertia_q=rot.T @ data.inertia_q,
                   modal_mass=rot.T @ data.modal_mass @ rot, coupling_0=rot.T @ data.coupling_0,
                   coupling=rot.T @ data.coupling @ rot, modal_stiffness=rot.T @ data.modal_stiffness @ rot,
                   marker_modes=data.marker_modes @ rot)
    for name in FIELDS:
        assert_close_relative(aligned.get(name, getattr(data, name)), getattr(old_data, name), RTOL, f"body data {name}")
    old_grad = np.zeros_like(np.asarray(reference["grad"]))
    old_grad[design_of] = np.asarray(grad)
    assert_close_relative(old_grad, reference["grad"], RTOL, "gradient of a span-invariant body-data scalar")


@eqx.filter_jit
def _pullback(case, x, g_scene):
    _, vjp = eqx.filter_vjp(case.scene, x)
    return vjp(g_scene)[0]


def test_unstructured_rod_gives_the_slider_crank_psi_and_gradient(tmp_path):
    """`value_and_grad(case, x)` is `value_and_grad_scene` at `p(x)` pulled back through the design map;
    it is run in these two parts so that the adjoint compiles once for both meshes (the scenes have
    the same structure), while each mesh has its own design map."""
    structured = fj.cases.slider_crank(12, 2, 4, 0.2)
    body, _, design_of = _shuffled_rod(structured.design, tmp_path, seed=2)
    unstructured = fj.cases.slider_crank(12, 2, 4, 0.2, rod=body)
    x = jnp.asarray(np.random.default_rng(4).uniform(0.2, 0.95, structured.n_design))
    method = fj.Adjoint(rtol=1e-11, atol=1e-18)
    gradient = eqx.filter_jit(lambda problem, scene: fj.value_and_grad_scene(problem, scene, method, rtol=1e-12,
                                                                             atol=1e-18))
    results = []
    for case, xc in ((structured, x), (unstructured, x[design_of])):
        scene = eqx.filter_jit(lambda case, x: case.scene(x))(case, xc)
        psi, g_scene = gradient(case.problem, scene)
        results.append((psi, _pullback(case, xc, g_scene)))
    (psi_s, grad_s), (psi_u, grad_u) = results
    assert_close_relative(psi_u, psi_s, RTOL, "psi, unstructured vs structured rod")
    assert_close_relative(np.asarray(grad_u), np.asarray(grad_s)[design_of], RTOL,
                          "adjoint gradient, unstructured vs structured rod (design variables matched)")
