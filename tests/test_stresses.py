"""Stress modes (issue 31): a body held by its reference conditions under a static load. The modal
stresses plus the stresses of the discarded modes' static contribution are the full FE model's static
stresses; the discarded part is the modal truncation error (stated in benchmarks/RESULTS.md)."""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import ffr_jax as fj
from ffr_jax._design.geometric_stiffness import element_stresses, gauss_gradients
from ffr_jax._outputs._stresses import modal_stresses, stress_modes, von_mises

EPS = np.finfo(float).eps


@pytest.mark.parametrize("n_modes", [6, 30])
def test_modal_stresses_plus_truncation_equal_the_static_fe_stresses(n_modes):
    case = fj.cases.slider_crank(20, 4, n_modes, 0.1)
    x = case.initial_design(0.5)
    body = case.design
    k, m = (np.asarray(a) for a in case.fe_matrices(x))
    free = np.setdiff1d(np.arange(k.shape[0]), case.fixed_dofs)
    # Gravity across the rod, held by its reference conditions (hinged-hinged: statically determinate).
    f = np.zeros(k.shape[0])
    f[1::2] = -9.81 * (m @ np.tile([0.0, 1.0], k.shape[0] // 2))[1::2]
    u = np.zeros_like(f)
    u[free] = np.linalg.solve(k[np.ix_(free, free)], f[free])
    phi = np.asarray(body.modes(x).modes)
    q = np.linalg.solve(phi.T @ k @ phi, phi.T @ f)  # the modal static solution (Ritz)
    modal = modal_stresses(stress_modes(body, x), jnp.asarray(q))
    # The discarded eigenmodes' part of the static solution, sum_{k > n} phi_k phi_k^T f / lambda_k.
    lam, vec = scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)])
    rest = np.zeros_like(f)
    rest[free] = vec[:, n_modes:] @ ((vec[:, n_modes:].T @ f[free]) / lam[n_modes:])
    youngs, _ = body.element_values(x)
    grads, _ = gauss_gradients(body.model)
    full = element_stresses(body.model, youngs, jnp.asarray(u), grads)
    remainder = element_stresses(body.model, youngs, jnp.asarray(rest), grads)
    # Three backward-stable solutions (static solve, eigen-solution, Ritz solve) each to n eps
    # lambda_max / lambda_1 relative (the spread of the pencil; TOLERANCES.md, static modes), 2x for the
    # products formed again. Measured 5e-12 (6 modes), 4e-12 (30) against a bound of ~1e-7.
    bound = 2 * len(free) * EPS * lam[-1] / lam[0]
    scale = float(jnp.max(jnp.abs(full)))
    err = float(jnp.max(jnp.abs(modal + remainder - full)))
    assert err <= bound * scale, f"modal + truncated stresses vs static FE stresses: {err / scale:.3e} > {bound:.3e}"
    # The truncation itself is a real, nonzero error (stresses converge slower than displacements).
    truncation = float(jnp.max(jnp.abs(von_mises(modal) - von_mises(full))) / jnp.max(von_mises(full)))
    assert bound < truncation < 0.1, f"von Mises truncation error {truncation:.3e} with {n_modes} modes"


def test_von_mises_of_uniaxial_and_shear_stress():
    # sqrt(s^2) = |s| for uniaxial stress and sqrt(3) tau for pure shear (exact up to one rounding).
    sigma = jnp.array([[2.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 1.5]])
    np.testing.assert_allclose(von_mises(sigma), [2.0, 3.0, np.sqrt(3) * 1.5], rtol=4 * EPS)


def test_stresses_along_the_motion_refuse_a_rigid_body_index():
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    x = case.initial_design(0.5)
    traj = fj.simulate(case, x, ts=jnp.linspace(0.0, 0.1, 3))
    sigma = fj.stresses(case, traj, x)
    assert sigma.shape == (3, case.mesh.n_elements, 4, 3) and bool(jnp.all(jnp.isfinite(sigma)))
    with pytest.raises(ValueError, match="not the designed body"):
        fj.stresses(case, traj, x, body=1)
