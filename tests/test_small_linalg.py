"""The tiny-matrix linear algebra of the equations of motion above the unrolled size (LAPACK path)."""

import jax
import jax.numpy as jnp
import numpy as np

from ffr_jax._small_linalg import UNROLL_MAX, matmul, spd_solve


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
