"""The tiny-matrix linear algebra of the equations of motion above the unrolled size (LAPACK path)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ffr_jax._dynamics._small_linalg import UNROLL_MAX, factored_solve, lu_factor, matmul, spd_solve


def _spd(n, seed):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, n))
    return jnp.asarray(a @ a.T + n * np.eye(n)), jnp.asarray(rng.standard_normal(n))


def test_matmul_above_the_unrolled_size_is_the_matrix_product():
    a, _ = _spd(UNROLL_MAX + 8, 0)
    b = jnp.asarray(np.random.default_rng(1).standard_normal((UNROLL_MAX + 8, 5)))
    # Same products in another order of summation: a few ulps of the 20-term sums.
    np.testing.assert_allclose(matmul(a, b), np.asarray(a) @ np.asarray(b), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(matmul(a, b[:, 0]), np.asarray(a) @ np.asarray(b[:, 0]), rtol=1e-13, atol=1e-13)


def test_spd_solve_derivative_above_the_unrolled_size():
    # d(A^-1 b) = A^-1 (db - dA A^-1 b) for a symmetric tangent dA (closed form), and the Jacobian
    # by vmapped tangents equals the one tangent at a time. The matrices are well conditioned
    # (cond < 10), so 1e-12 is a few hundred ulps of the solution's size.
    n = UNROLL_MAX + 8
    a, b = _spd(n, 2)
    da, db = _spd(n, 3)
    x = np.linalg.solve(np.asarray(a), np.asarray(b))
    value, tangent = jax.jvp(spd_solve, (a, b), (da, db))
    expected = np.linalg.solve(np.asarray(a), np.asarray(db) - np.asarray(da) @ x)
    np.testing.assert_allclose(value, x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(tangent, expected, rtol=1e-12, atol=1e-12)
    jac = jax.jacfwd(spd_solve, argnums=1)(a, b)
    np.testing.assert_allclose(jac, np.linalg.inv(np.asarray(a)), rtol=1e-12, atol=1e-12)
    cotangent = jax.grad(lambda bb: spd_solve(a, bb) @ b)(b)
    np.testing.assert_allclose(cotangent, np.linalg.solve(np.asarray(a), np.asarray(b)), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n", [6, UNROLL_MAX + 2], ids=["unrolled", "lapack"])
def test_factored_solve_second_derivatives_in_both_orders(n):
    # `w . A(u)^-1 b(u)` through `factored_solve` (its own rule in first order, the elimination under
    # forward mode over reverse mode) against `jnp.linalg.solve`: value, gradient and a Hessian-vector
    # product by reverse over forward and by forward over reverse. With the factors `stop_gradient`-ed,
    # forward over reverse lost the factors' dependence on u: O(1) off here (entries 1.0 and 1.7 relative). Well-conditioned
    # matrices (cond < 10), second derivatives of size ~1: 1e-11 is ~1e4 ulps.
    a0, b0 = _spd(n, 4)
    a1, b1 = _spd(n, 5)
    w = jnp.asarray(np.random.default_rng(6).standard_normal(n))

    def parts(u):
        return a0 + u[0] * a1 + u[1] ** 2 * jnp.eye(n), b0 + jnp.sin(u[2]) * b1

    def with_factors(u):
        a, b = parts(u)
        return w @ factored_solve(a, lu_factor(a), b)

    def reference(u):
        return w @ jnp.linalg.solve(*parts(u))

    @jax.jit
    def derivatives(u, v):
        out = [fn(u) for fn in (with_factors, reference)]
        out += [jax.grad(fn)(u) for fn in (with_factors, reference)]
        out += [jax.grad(lambda x: jax.jvp(with_factors, (x,), (v,))[1])(u),
                jax.jvp(jax.grad(with_factors), (u,), (v,))[1], jax.jvp(jax.grad(reference), (u,), (v,))[1]]
        return out

    value, value_ref, grad, grad_ref, rof, for_, hvp_ref = derivatives(jnp.asarray([0.3, 0.7, 0.2]),
                                                                       jnp.asarray([1.0, -0.5, 2.0]))
    np.testing.assert_allclose(value, value_ref, rtol=1e-11)
    np.testing.assert_allclose(grad, grad_ref, rtol=1e-11, atol=1e-11 * float(jnp.max(jnp.abs(grad_ref))))
    scale = float(jnp.max(jnp.abs(hvp_ref)))
    np.testing.assert_allclose(rof, hvp_ref, rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(for_, hvp_ref, rtol=0, atol=1e-11 * scale)
