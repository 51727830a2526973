"""Design constraints: values against independent routes, exact gradients against finite differences,
bounds that no design can meet refused at construction, and MMA runs that meet them or report why not."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj

from helpers import random_design, small_case


@pytest.fixture(scope="module")
def case():
    # The suite's small case (12 x 2, dense FE: the modal analysis is a small dense eigenproblem).
    return small_case()


@pytest.fixture(scope="module")
def filt(case):
    return fj.DensityFilter(case.design, 1.5)


def central_differences(fun, x, step=1e-6):
    return jax.jit(jax.vmap(lambda e: (fun(x + step * e) - fun(x - step * e)) / (2 * step)))(jnp.eye(x.shape[0]))


# Central differences of a smooth function with step 1e-6: truncation ~ step^2 |f'''| ~ 1e-12 and
# round-off ~ 1e-16 |f| / step ~ 1e-10 relative to the largest entry; 1e-6 leaves a wide margin.
FD_TOL = 1e-6


def test_mass_is_the_mass_of_the_consistent_mass_matrix(case):
    constraint = fj.MassConstraint(case.design, 3.0)
    both = jax.jit(lambda x: (constraint.mass(x), case.body_data(x).mass))
    for seed, (low, high) in enumerate([(0.2, 0.95), (0.01, 0.3)]):  # the second crosses the SIMP switch at 0.1
        # e_x^T M e_x of the body data: the same SIMP law, summed through the consistent mass matrix.
        mass, body_mass = both(random_design(case, seed, low, high))
        np.testing.assert_allclose(mass, body_mass, rtol=1e-13, err_msg="sum rho_e V_e against e_x^T M e_x")
    lightest, heaviest = constraint.range
    mesh = case.mesh
    interface = 2 * mesh.ny * mesh.dx * mesh.dy * case.design.model.thickness * case.material.density
    assert interface < lightest < interface * 1.001, "the lightest design is the interface columns plus voids"
    np.testing.assert_allclose(heaviest, mesh.length * mesh.height * case.design.model.thickness * case.material.density,
                               rtol=1e-14, err_msg="mass of the solid rod")


def test_mass_gradient_matches_finite_differences(case, filt):
    x = random_design(case, 3)
    for lower in (False, True):
        constraint = fj.MassConstraint(case.design, 3.0, lower=lower, filter=filt)
        g, grad = jax.jit(lambda x: constraint.value_and_grad(x))(x)
        fd = central_differences(lambda x: constraint.value_and_grad(x)[0], x)
        np.testing.assert_allclose(grad, fd, rtol=FD_TOL, atol=FD_TOL * np.abs(fd).max(),
                                   err_msg=f"mass gradient through the filter (lower={lower})")
        m = float(constraint.mass(filt(x)))
        np.testing.assert_allclose(g, 1 - m / 3.0 if lower else m / 3.0 - 1, rtol=1e-14, err_msg="normalisation")
        assert "mass" in constraint.describe(float(g))


def test_unreachable_mass_bounds_are_refused(case):
    lightest, heaviest = fj.MassConstraint(case.design, 1.0).range
    with pytest.raises(ValueError, match="lightest design"):
        fj.MassConstraint(case.design, 0.99 * lightest)
    with pytest.raises(ValueError, match="solid body weighs"):
        fj.MassConstraint(case.design, 1.01 * heaviest, lower=True)
    with pytest.raises(ValueError, match="positive"):
        fj.MassConstraint(case.design, -1.0)


@pytest.mark.parametrize("beta", [None, 4.0])
def test_volume_inequality_gradient_matches_finite_differences(case, filt, beta):
    projection = None if beta is None else fj.HeavisideProjection(x_min=case.material.x_min)
    constraint = fj.VolumeConstraint(0.4, x_min=case.material.x_min, filter=filt, projection=projection)
    x = random_design(case, 4)
    g, grad = jax.jit(lambda x: constraint.value_and_grad(x, beta))(x)
    np.testing.assert_allclose(g, constraint.fraction(x, beta) / 0.4 - 1, rtol=1e-14, err_msg="g of the volume")
    fd = central_differences(lambda x: constraint.value_and_grad(x, beta)[0], x)
    np.testing.assert_allclose(grad, fd, rtol=FD_TOL, atol=FD_TOL * np.abs(fd).max(), err_msg=f"volume (beta {beta})")


def test_frequency_constraint_value_and_gradient(case, filt):
    projection = fj.HeavisideProjection(x_min=case.material.x_min)
    constraint = fj.FrequencyConstraint(case, 20.0, filter=filt, projection=projection)
    x, beta = random_design(case, 5), 2.0
    g, grad = jax.jit(lambda x, beta: constraint.value_and_grad(x, beta))(x, beta)
    f1 = case.frequencies(fj.physical_densities(x, filt, projection, beta))[0]
    # Jitted against eager eigen-solutions: round-off of the Cholesky-transformed eigenproblem (4e-11 seen).
    np.testing.assert_allclose(g, 1 - f1 / 20.0, rtol=1e-9, err_msg="g = 1 - f_1 / f_min")
    # f_1 is a simple eigenvalue (f_2 / f_1 ~ 4 on the hinged rod), smooth in x, but the eigen-solution
    # carries ~4e-11 relative round-off (above), which central differences divide by the step: 5e-5 at
    # step 1e-6. At step 3e-4 round-off (~1.5e-7) and truncation (~7e-8, from 7e-5 at step 1e-2) are
    # balanced; the bound 1e-5 of the largest entry keeps a factor 50.
    fd = central_differences(jax.jit(lambda x: constraint.value_and_grad(x, beta)[0]), x, step=3e-4)
    np.testing.assert_allclose(grad, fd, rtol=0.0, atol=1e-5 * np.abs(fd).max(),
                               err_msg="eigenvalue derivative of f_1 through filter and projection")
    assert "f_1" in constraint.describe(float(g))


def test_frequency_bound_of_every_design():
    case = fj.cases.slider_crank(12, 4, 2, 0.2)  # four element rows: room for a sandwich
    constraint = fj.FrequencyConstraint(case, 1.0)
    bound, solid = constraint.upper_bound, constraint.solid
    f1 = jax.jit(lambda x: case.frequencies(x)[0])
    # The Rayleigh-quotient bound holds for any design; the solid rod is not the stiffest in f_1: a
    # sandwich (solid outer rows, voids in between but for webs every 4 columns) is lighter where the
    # rod moves (91.6 Hz against the solid rod's 86.0 Hz).
    sandwich = np.ones((4, 10))
    sandwich[1:3] = case.material.x_min
    sandwich[:, ::4] = 1.0
    assert float(f1(jnp.asarray(sandwich.ravel()))) > 1.05 * solid, "a sandwich with webs beats the solid rod's f_1"
    frequencies = [float(f1(random_design(case, s, 0.01, 1.0))) for s in range(5)]
    frequencies += [float(f1(case.initial_design(v))) for v in (0.01, 0.5, 1.0)]
    frequencies.append(float(f1(jnp.asarray(sandwich.ravel()))))
    assert max(frequencies) < bound, f"f_1 of designs {frequencies} above the bound {bound}"
    np.testing.assert_allclose(solid, frequencies[-2], rtol=1e-9, err_msg="f_1 of the solid rod")
    with pytest.raises(ValueError, match="No design of this body reaches"):
        fj.FrequencyConstraint(case, 1.01 * bound)
    with pytest.warns(UserWarning, match="above f_1"):
        fj.FrequencyConstraint(case, 1.5 * solid)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fj.FrequencyConstraint(case, 0.9 * solid)  # no warning below the solid rod's f_1


def test_function_constraint_normalises_and_passes_beta():
    calls = []

    def fun(x, beta=None):
        calls.append(beta)
        return jnp.sum(x**2), 2 * x

    x = jnp.asarray([0.5, 1.0])
    upper = fj.FunctionConstraint(fun, 2.0, name="energy")
    g, grad = upper.value_and_grad(x)
    np.testing.assert_allclose([g, *grad], [1.25 / 2 - 1, 0.5, 1.0], rtol=1e-15)
    g, grad = fj.FunctionConstraint(fun, 2.0, lower=True).value_and_grad(x, 3.0)
    np.testing.assert_allclose([g, *grad], [1 - 1.25 / 2, -0.5, -1.0], rtol=1e-15)
    assert calls == [None, 3.0], "fun(x) without a projection, fun(x, beta) with one"
    g, _ = fj.FunctionConstraint(fun, 0.0).value_and_grad(x)
    assert g == pytest.approx(1.25), "a zero bound is not scaled"
    assert "energy 1.25" in upper.describe(float(upper.value_and_grad(x)[0]))
    with pytest.raises(ValueError, match="function"):
        fj.FunctionConstraint(3.0, 1.0)
