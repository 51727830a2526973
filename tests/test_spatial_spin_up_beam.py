"""Kane, Ryan and Banerjee's spin-up beam in space (issue 26): geometric stiffening of a spatial flexible body.

The solid H11 beam of `fj.cases.spin_up_beam` (chordwise and flapwise bending, gravity along the spin axis) against
the independent Rayleigh–Ritz model of `tests/spin_up_reference.py` with as many Ritz functions per direction as the
FE body has mode pairs (the same truncation), with and without the [`SpatialGeometricStiffening`][]; and the six
unit load cases of `solid_centrifugal_geometric_stiffness` against a direct solve with the full centrifugal load, and
their exact scaling in the design (the JVP of `K_k` along the density is `K_k`, along a uniform Young's modulus 0).
benchmarks/RESULTS.md ("Spin-up beam") has the full-size comparison and its mesh convergence.

The refusals of bad input run in the default suite (0.3 s). Marked slow: the simulation compiles once (~15-20 s; the run without stiffening is the same program with the
stiffening matrices set to zero, which is the same equations as leaving the force out).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import ffr_jax as fj
from ffr_jax._design.solid_assembly import solid_dense_matrix
from ffr_jax._design.solid_geometric_stiffness import (angular_velocity_products, hex_gauss_gradients,
                                                       solid_modal_geometric_stiffness, solid_stress_tensors)

import spin_up_reference as ritz

NX, N_MODES, T1 = 40, 4, 10.0
N_RITZ = N_MODES // 2  # the FE modes come in degenerate pairs (chordwise, flapwise) of the square section
TS = np.linspace(0.0, T1, 201)
RTOL, ATOL = 1e-9, 1e-11
# The integration error of the state at rtol 1e-9 over ~10^3 steps: ~1e-7 of deflections of O(1 m).
SOLVER = 1e-6


@pytest.fixture(scope="module")
def runs():
    problem = fj.cases.spin_up_beam(NX, N_MODES, T1)
    force = problem.scene.forces[1]
    assert isinstance(force, fj.SpatialGeometricStiffening)
    unstiffened = eqx.tree_at(lambda p: p.scene.forces[1].modal_geometric_stiffness, problem,
                              jnp.zeros_like(force.modal_geometric_stiffness))
    out = {}
    for stiffening, pb in ((True, problem), (False, unstiffened)):
        traj = fj.simulate(pb, ts=jnp.asarray(TS), rtol=RTOL, atol=ATOL)
        out[stiffening] = np.asarray(traj.positions)[:, 7:] @ np.asarray(pb.scene.bodies[0].data.marker_modes[1]).T
    return problem, out


def _ritz_eigenvalues(beam, rate, stiffening):
    """`omega^2` of the Ritz model at spin `rate`: chordwise (softened by `-rate^2 M`) and flapwise, sorted by mode."""
    s = 1.0 if stiffening else 0.0
    chord = np.linalg.eigvals(np.linalg.solve(beam.mass, beam.stiffness_v + rate**2 * (s * beam.geometric - beam.mass)))
    flap = np.linalg.eigvals(np.linalg.solve(beam.mass, beam.stiffness_w + s * rate**2 * beam.geometric))
    return np.sort(chord.real), np.sort(flap.real)


def _fe_eigenvalues(problem, rate, stiffening):
    """`omega^2` of the FE body's modal equations at spin `rate` about `z`: `K_qq + rate^2 (s K_zz - S)`, with `S`
    the in-plane part `C2_xx + C2_yy` of the centrifugal term of `h_q`; in chordwise/flapwise pairs."""
    data = problem.scene.bodies[0].data
    k_zz = np.asarray(problem.scene.forces[1].modal_geometric_stiffness[2]) if stiffening else 0.0
    c2 = np.asarray(data.second_moment_qq)
    soft = c2[:, :, 0, 0] + c2[:, :, 1, 1]
    lam = np.linalg.eigvals(np.linalg.solve(np.asarray(data.modal_mass), np.asarray(data.modal_stiffness)
                                            + rate**2 * (k_zz - soft)))
    lam = np.sort(lam.real).reshape(-1, 2)
    return lam[:, 0], lam[:, 1]  # the softened (chordwise) one of each pair is the lower


def _tolerance(problem, beam, window, stiffening, direction):
    """The bound on `|tip_FE - tip_Ritz|` over `window` from the FE body's eigenvalue errors.

    Decompose the Ritz response into its modes (eigenvectors of `(K, M)` at rest): mode `k` contributes at most
    `A_k` to the tip. A relative error `e_k` of its `omega_k^2` changes a quasi-static response by `e_k A_k` and
    dephases an oscillation by `omega_k e_k t / 2` (at most `2 A_k`). `e_k` is the largest over the spin rates of the
    window (FE modal equations against the Ritz ones), `omega_k` the largest frequency. Twice the sum covers the
    mode-shape error of the mesh (of the order of its eigenvalue error) and the floating frame's second-order
    inertia terms, which the linear Ritz model does not have; plus the solver's error.
    """
    k_index = 0 if direction == "v" else 1
    times = TS[window]
    rates = np.array([ritz.spin_up(t, **ritz.KANE_SPIN_UP)[1] for t in times[:: max(1, times.size // 40)]])
    errors, omegas = np.zeros(N_RITZ), np.zeros(N_RITZ)
    for rate in rates:
        fe = _fe_eigenvalues(problem, rate, stiffening)[k_index]
        rz = _ritz_eigenvalues(beam, rate, stiffening)[k_index][:N_RITZ]
        errors = np.maximum(errors, np.abs(fe / rz - 1.0))
        omegas = np.maximum(omegas, np.sqrt(np.abs(rz)))
    stiffness = beam.stiffness_v if direction == "v" else beam.stiffness_w
    modes = scipy.linalg.eigh(stiffness, beam.mass)[1]  # M-orthonormal, ascending
    coords = beam.coordinates(times, stiffening=stiffening, gravity=9.81, **ritz.KANE_SPIN_UP)[k_index]
    amplitudes = np.max(np.abs((coords @ beam.mass @ modes) * (beam.tip @ modes)), axis=0)
    return 2.0 * np.sum(amplitudes * (np.minimum(2.0, omegas * errors * times[-1] / 2.0) + errors)) + SOLVER


@pytest.mark.slow
@pytest.mark.parametrize("stiffening", [True, False])
def test_spin_up_beam_tip_deflections_match_ritz(runs, stiffening):
    problem, tips = runs
    beam = ritz.RitzBeam(N_RITZ, **ritz.KANE_BEAM)
    v, w = beam.tip_deflections(TS, stiffening=stiffening, gravity=9.81, **ritz.KANE_SPIN_UP)
    # Without stiffening the chordwise motion diverges once the spin passes the first bending frequency: compare up
    # to a chordwise tip deflection of 1 m (t ~ 6.8 s), where both models are still near their linear range.
    window = np.ones(TS.size, bool) if stiffening else TS <= TS[np.argmax(np.abs(v) > 1.0)]
    tip = tips[stiffening]
    for name, k, reference in (("chordwise v", 1, v), ("flapwise w", 2, w)):
        error = np.max(np.abs(tip[window, k] - reference[window]))
        bound = _tolerance(problem, beam, window, stiffening, name[-1])
        print(f"stiffening={stiffening} {name}: max |FE - Ritz| = {error:.3g} m, bound {bound:.3g} m")
        assert error <= bound, f"{name} tip deflection (stiffening={stiffening}) differs from Ritz by {error:.3g} m > {bound:.3g} m"
    assert np.max(np.abs(tip[:, 0])) < 1e-8, "the tip moves axially (the modes are bending modes: no axial part)"
    if stiffening:
        # The stiffened beam follows the spin: Kane et al.'s chordwise tip deflection dips to about -0.57 m (t ~ 7 s)
        # and is on its way back at t = 10 s; unstiffened it diverges (the "wrong trend" of the linear floating frame).
        assert -0.7 < tip[:, 1].min() < -0.4 and tip[-1, 1] > 0.75 * tip[:, 1].min()
    else:
        assert np.max(np.abs(tip[:, 1])) > 10.0


def _direct_geometric_stiffness(model, youngs, densities, modes, fixed, omega):
    """`Phi^T K_G(sigma(omega)) Phi` from one static solve with the full centrifugal load `-rho omega x (omega x c)`
    (built with cross products, not from the six unit fields)."""
    c = np.asarray(model.coordinates)
    field = -np.cross(omega, np.cross(omega, c))
    k = np.asarray(solid_dense_matrix(model, youngs, "stiffness"))
    m = np.asarray(solid_dense_matrix(model, densities, "mass"))
    free = np.setdiff1d(np.arange(model.n_dof), fixed)
    u = np.zeros(model.n_dof)
    u[free] = np.linalg.solve(k[np.ix_(free, free)], (m @ field.ravel())[free])
    grads, weights = hex_gauss_gradients(model)
    return np.asarray(solid_modal_geometric_stiffness(
        model, solid_stress_tensors(model, youngs, jnp.asarray(u), grads), modes, grads, weights))


@pytest.fixture(scope="module")
def small_beam():
    mesh = fj.box_grid(6, 2, 1, 1.0, 0.1, 0.05)
    model = fj.SolidFEModel(mesh, fj.H8(), poisson=0.3)
    youngs = jnp.full(model.n_elements, 2e11)
    densities = jnp.linspace(7000.0, 8000.0, model.n_elements)
    root = np.flatnonzero(np.isclose(mesh.nodes[:, 0], 0.0))
    fixed = np.sort(np.concatenate([3 * root, 3 * root + 1, 3 * root + 2]))
    modes = jnp.asarray(np.random.default_rng(3).normal(size=(model.n_dof, 3))).at[fixed].set(0.0)
    return model, youngs, densities, modes, tuple(int(d) for d in fixed)


@pytest.mark.slow
def test_six_unit_cases_equal_the_full_centrifugal_load(small_beam):
    model, youngs, densities, modes, fixed = small_beam
    cases = np.asarray(fj.solid_centrifugal_geometric_stiffness(model, youngs, densities, modes, fixed))
    for omega in (np.array([0.0, 0.0, 3.0]), np.array([1.3, -0.7, 2.1])):
        combined = np.einsum("k,kqr->qr", np.asarray(angular_velocity_products(jnp.asarray(omega))), cases)
        direct = _direct_geometric_stiffness(model, youngs, densities, modes, np.asarray(fixed), omega)
        # The same linear solves with the loads combined before or after: equal to round-off of the dense solve,
        # ~cond(K_ff) eps ~ 1e-12 here (a 6 x 2 x 1 mesh); a wrong sign or a swapped pair of products is O(1).
        assert np.max(np.abs(combined - direct)) <= 1e-9 * np.max(np.abs(direct)), f"omega = {omega}"
        assert np.max(np.abs(combined - combined.T)) <= 1e-12 * np.max(np.abs(direct)), "K_geo is symmetric"


@pytest.mark.slow
def test_unit_cases_carry_exact_design_derivatives(small_beam):
    model, youngs, densities, modes, fixed = small_beam
    f = lambda e, r: fj.solid_centrifugal_geometric_stiffness(model, e, r, modes, fixed)
    value, along_density = jax.jvp(lambda r: f(youngs, r), (densities,), (densities,))
    _, along_youngs = jax.jvp(lambda e: f(e, densities), (youngs,), (youngs,))
    scale = np.max(np.abs(np.asarray(value)))
    # The load is linear in rho and the stress of a load is independent of a uniform scale of E (modes held), so
    # d K / d c at c = 1 is K along rho -> c rho and 0 along E -> c E, exactly; round-off ~1e-12 of K.
    assert np.max(np.abs(np.asarray(along_density - value))) <= 1e-10 * scale
    assert np.max(np.abs(np.asarray(along_youngs))) <= 1e-10 * scale


def test_unit_cases_refuse_bad_input():
    # Cheap (no compile): the refusals come before anything is traced.
    hexes = fj.box_grid(2, 1, 1, 1.0, 0.1, 0.1)
    model = fj.SolidFEModel(hexes, fj.H8())
    values, modes = jnp.ones(model.n_elements), jnp.zeros((model.n_dof, 1))
    node = int(np.flatnonzero(np.isclose(hexes.nodes[:, 0], 0.0))[0])
    with pytest.raises(ValueError, match="fixed_dofs must name supports"):
        fj.solid_centrifugal_geometric_stiffness(model, values, values, modes, ())
    with pytest.raises(ValueError, match="do not hold the body"):  # one node held: the body can turn about it
        fj.solid_centrifugal_geometric_stiffness(model, values, values, modes, (3 * node, 3 * node + 1, 3 * node + 2))
    tets = fj.SolidFEModel(fj.hex_to_tet10(hexes), fj.Tet10())
    with pytest.raises(ValueError, match="hexahedral mesh"):
        fj.solid_centrifugal_geometric_stiffness(tets, jnp.ones(tets.n_elements), jnp.ones(tets.n_elements),
                                                 jnp.zeros((tets.n_dof, 1)), (0, 1, 2))
