"""The block lower-triangular structure of `C_d` (`ffr_jax/_dynamics/_block_triangular.py`) and block solves.

Exactness: a block substitution performs the same eliminations as a dense LU on a block-triangular matrix, in
another order; on well-conditioned random 9 x 9 matrices (condition < 1e3 here) both solves agree to
`cond * n * eps ~ 1e-12`, bound 1e-10.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ffr_jax._dynamics._block_triangular import block_structure
from ffr_jax._dynamics._small_linalg import block_lu_factor, lu_solve

SOLVE_RTOL = 1e-10


def _block_matrix(rng):
    """A 9 x 9 matrix with rows and columns shuffled from a block lower-triangular one of blocks 4, 2, 3."""
    sizes = (4, 2, 3)
    a = np.zeros((9, 9))
    start = 0
    for n in sizes:
        a[start:start + n, :start + n] = rng.standard_normal((n, start + n))
        a[start:start + n, start:start + n] += 4.0 * np.eye(n)
        start += n
    rows, cols = rng.permutation(9), rng.permutation(9)
    return a[np.ix_(rows, cols)]


def test_structure_found_and_solves_equal_dense():
    rng = np.random.default_rng(3)
    a = _block_matrix(rng)
    blocks = block_structure(a != 0.0)
    assert [len(c) for _, c in blocks] == [4, 2, 3]
    for k, (rows, _) in enumerate(blocks):  # no entries in the columns of later blocks
        later = [c for _, cols in blocks[k + 1:] for c in cols]
        assert not np.any(a[np.ix_(rows, later)])
    b = rng.standard_normal((9, 2))

    @jax.jit  # one program: op by op, the unrolled eliminations cost seconds of dispatch
    def solves(a, b):
        lu = block_lu_factor(a, blocks)
        return lu_solve(lu, b), lu_solve(lu, b, trans=1), lu.det()

    x, x_t, det = solves(jnp.asarray(a), jnp.asarray(b))
    for x, matrix in ((x, a), (x_t, a.T)):
        x = np.asarray(x)
        np.testing.assert_allclose(x, np.linalg.solve(matrix, b), rtol=SOLVE_RTOL, atol=SOLVE_RTOL * np.abs(x).max())
    np.testing.assert_allclose(float(det), np.linalg.det(a), rtol=SOLVE_RTOL)


def test_irreducible_pattern_is_one_block():
    assert block_structure(np.ones((5, 5), bool)) is None
    # Structurally singular (a zero column): no block form, the dense path.
    pattern = np.ones((3, 3), bool)
    pattern[:, 1] = False
    assert block_structure(pattern) is None
