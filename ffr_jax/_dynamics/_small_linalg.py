"""Dense linear algebra for the tiny matrices of the equations of motion, unrolled into plain jnp ops.

A multibody model solves with a handful of tiny matrices per evaluation of its vector field:
the constraint Jacobian of the dependent coordinates `C_d` (`n_c x n_c`, 3 for the slider–crank)
and the minimal mass matrix `Mbar` (`f x f`, 6 for the reference case). XLA:CPU runs every
LAPACK routine as a separate custom call with a fixed cost of a few microseconds, more than the
arithmetic of such a matrix; an elimination unrolled over the static size fuses with the
surrounding code instead. Above `UNROLL_MAX` the LAPACK routines are used.

All functions here are compositions of differentiable jnp operations (the pivot choice is
piecewise constant), so `jax.jvp`, `jax.vjp` and `jax.vmap` apply to them as to any jnp code.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

# 16 rather than 12: the spatial slider-crank's 14 dependent coordinates (rod and driven crank, `R, p` each) made
# `C_d` a LAPACK matrix, and under `jax.vmap` (the adjoint's quadrature, Jacobians by `jax.jacfwd`) batched LAPACK
# kernels deadlock XLA's CPU thread pool on a 2-core machine even with the scheduler flag of `_xla_flags` set: both
# pool threads waited in batched `trsm` at 0 % CPU (tests/test_spatial_flexible_slider_crank.py, 20 minutes, issue 26).
UNROLL_MAX = 16


CLOSED_FORM_MAX = 3


class LU(eqx.Module):
    """A factorisation of a square matrix `A` for solves and its determinant.

    For `n <= CLOSED_FORM_MAX` it holds `A^-1` in closed form (adjugate over determinant, one
    fused kernel; `perm` is unused and `sign` holds `det A`). Otherwise `P A = L U`: `lu` holds
    `L` (unit diagonal, below) and `U` (on and above), `perm` the row order (`P A = A[perm]`),
    `sign` the determinant of `P`.
    """

    lu: jnp.ndarray
    perm: jnp.ndarray
    sign: jnp.ndarray

    @property
    def n(self) -> int:
        return self.lu.shape[0]

    def det(self):
        """`det A`."""
        if self.n <= CLOSED_FORM_MAX:
            return self.sign
        return self.sign * jnp.prod(jnp.diagonal(self.lu))


def _adjugate(a):
    """`(adj A, det A)` of a `1 x 1`, `2 x 2` or `3 x 3` matrix, in a few elementwise operations."""
    n = a.shape[0]
    if n == 1:
        return jnp.ones_like(a), a[0, 0]
    if n == 2:
        adj = jnp.array([[1.0, -1.0], [-1.0, 1.0]], a.dtype) * a[::-1, ::-1].T
        return adj, a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    # Column i of adj A is the cross product of rows i+1 and i+2 (indices mod 3).
    b, c = jnp.roll(a, -1, axis=0), jnp.roll(a, -2, axis=0)
    cross = jnp.roll(b, -1, axis=1) * jnp.roll(c, -2, axis=1) - jnp.roll(b, -2, axis=1) * jnp.roll(c, -1, axis=1)
    return cross.T, jnp.sum(a[0] * cross[0])


def lu_factor(a) -> LU:
    """Closed-form inverse (`n <= CLOSED_FORM_MAX`), Gaussian elimination with partial pivoting, or
    LAPACK `getrf` (`n > UNROLL_MAX`).

    A zero pivot (a singular matrix) is kept in `U` (so [`LU.det`][] is zero) and not divided by,
    so that no NaN appears; solves with such a factorisation are meaningless, as with LAPACK.
    """
    n = a.shape[0]
    if n <= CLOSED_FORM_MAX:
        adj, det = _adjugate(a)
        return LU(lu=adj / jnp.where(det == 0, 1.0, det), perm=jnp.arange(n), sign=det)
    if n > UNROLL_MAX:
        lu, pivots, perm = jax.lax.linalg.lu(a)
        swaps = jnp.sum(pivots != jnp.arange(n, dtype=pivots.dtype))
        return LU(lu=lu, perm=perm, sign=jnp.where(swaps % 2 == 0, 1.0, -1.0).astype(a.dtype))
    rows = jnp.arange(n)
    perm = rows
    sign = jnp.ones((), a.dtype)
    for k in range(n):
        if k < n - 1:
            p = jnp.argmax(jnp.where(rows >= k, jnp.abs(a[:, k]), -1.0))
            is_k, is_p = (rows == k)[:, None], (rows == p)[:, None]
            row_k, row_p = a[k], a[p]
            a = jnp.where(is_k, row_p[None, :], jnp.where(is_p, row_k[None, :], a))
            perm = jnp.where(rows == k, perm[p], jnp.where(rows == p, perm[k], perm))
            sign = jnp.where(p != k, -sign, sign)
            pivot = a[k, k]
            below = rows > k
            factors = jnp.where(below, a[:, k] / jnp.where(pivot == 0, 1.0, pivot), 0.0)
            update = jnp.where(rows > k, a[k], 0.0)
            a = a - factors[:, None] * update[None, :]
            a = jnp.where(below[:, None] & (rows == k)[None, :], factors[:, None], a)
    return LU(lu=a, perm=perm, sign=sign)


class BlockLU(eqx.Module):
    """Factors of a square matrix `A` whose rows and columns permute to block lower-triangular form.

    Block `k` is the submatrix `A[rows_k][:, cols_k]`; rows of block `k` have no entries in the columns of later
    blocks. `diagonal[k]` is the [`LU`][] of block `k`, `lower[k]` the rows of block `k` in the columns of the
    earlier blocks (in their order), `(n_k, sum_{j<k} n_j)`. Solves are block forward (or, transposed, backward)
    substitution: `x_k = A_kk^-1 (b[rows_k] - A[rows_k, cols_<k] x_<k)`.
    """

    diagonal: tuple[LU, ...]
    lower: tuple[jnp.ndarray, ...]
    blocks: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = eqx.field(static=True)

    @property
    def n(self) -> int:
        return sum(len(cols) for _, cols in self.blocks)

    def det(self):
        """`det A` (the product of the blocks' determinants and the signs of the two permutations)."""
        rows = [r for rows, _ in self.blocks for r in rows]
        cols = [c for _, cols in self.blocks for c in cols]
        sign = _permutation_sign(rows) * _permutation_sign(cols)
        out = jnp.asarray(float(sign), self.lower[0].dtype if self.lower else self.diagonal[0].lu.dtype)
        for lu in self.diagonal:
            out = out * lu.det()
        return out

    def solve(self, b, trans: int = 0):
        """`A^-1 b` (`trans=0`) or `A^-T b` (`trans=1`); `b` is `(n,)` or `(n, m)`."""
        sizes = [len(cols) for _, cols in self.blocks]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        parts = []
        if trans == 0:
            for k, (rows, _) in enumerate(self.blocks):
                rhs = b[np.asarray(rows)]
                if k:
                    done = parts[0] if k == 1 else jnp.concatenate(parts, axis=0)
                    rhs = rhs - matmul(self.lower[k], done)
                parts.append(lu_solve(self.diagonal[k], rhs))
            order = [c for _, cols in self.blocks for c in cols]
        else:
            parts = [None] * len(self.blocks)
            for k in reversed(range(len(self.blocks))):
                rhs = b[np.asarray(self.blocks[k][1])]
                for j in range(k + 1, len(self.blocks)):
                    rhs = rhs - matmul(self.lower[j][:, offsets[k]:offsets[k + 1]].T, parts[j])
                parts[k] = lu_solve(self.diagonal[k], rhs, trans=1)
            order = [r for rows, _ in self.blocks for r in rows]
        x = parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=0)
        return x[np.argsort(order)]


def _permutation_sign(order) -> int:
    order, sign, seen = list(order), 1, set()
    for start in range(len(order)):
        if start in seen:
            continue
        length, i = 0, start
        while i not in seen:
            seen.add(i)
            i = order[i]
            length += 1
        sign *= -1 if length % 2 == 0 else 1
    return sign


def block_lu_factor(a, blocks) -> BlockLU:
    """[`BlockLU`][] of `a` for a static block lower-triangular structure `blocks = ((rows_k, cols_k), ...)`
    (entries of `a` outside it are taken as zero): [`lu_factor`][] of each diagonal block."""
    diagonal, lower, done = [], [], []
    for rows, cols in blocks:
        a_rows = a[np.asarray(rows)]
        diagonal.append(lu_factor(a_rows[:, np.asarray(cols)]))
        lower.append(a_rows[:, np.asarray(done, dtype=int)])
        done.extend(cols)
    return BlockLU(diagonal=tuple(diagonal), lower=tuple(lower), blocks=tuple(blocks))


def matmul(a, b):
    """`a @ b` for tiny matrices (or a matrix and a vector), as a broadcast product and a sum.

    XLA:CPU hands every `dot` to a library kernel whose fixed cost exceeds the arithmetic of a
    9 x 9 product; the elementwise form fuses into a single loop kernel. Above `UNROLL_MAX` rows
    or columns the elementwise form materialises an `n^3` array (under `jax.vmap` of a Jacobian's
    tangents, one per tangent), so `dot` is used there.
    """
    if max(a.shape + b.shape) > UNROLL_MAX:
        return a @ b
    if b.ndim == 1:
        return jnp.sum(a * b[None, :], axis=1)
    return jnp.sum(a[:, :, None] * b[None, :, :], axis=1)


def _safe(d):
    return jnp.where(d == 0, 1.0, d)


def lu_solve(lu: "LU | BlockLU", b, trans: int = 0):
    """`A^-1 b` (`trans=0`) or `A^-T b` (`trans=1`) from [`lu_factor`][] or [`block_lu_factor`][]; `b` is `(n,)`
    or `(n, m)`."""
    if isinstance(lu, BlockLU):
        return lu.solve(b, trans)
    n = lu.n
    vector = b.ndim == 1
    x = b[:, None] if vector else b
    if n <= CLOSED_FORM_MAX:
        inv = lu.lu if trans == 0 else lu.lu.T
        x = jnp.sum(inv[:, :, None] * x[None, :, :], axis=1)
        return x[:, 0] if vector else x
    if n > UNROLL_MAX:
        perm_inv = jnp.zeros_like(lu.perm).at[lu.perm].set(jnp.arange(n, dtype=lu.perm.dtype))
        if trans == 0:
            x = jsl.solve_triangular(lu.lu, x[lu.perm], lower=True, unit_diagonal=True)
            x = jsl.solve_triangular(lu.lu, x, lower=False)
        else:
            x = jsl.solve_triangular(lu.lu, x, lower=False, trans=1)
            x = jsl.solve_triangular(lu.lu, x, lower=True, unit_diagonal=True, trans=1)[perm_inv]
        return x[:, 0] if vector else x
    a = lu.lu
    rows = jnp.arange(n)
    if trans == 0:
        x = x[lu.perm]
        for k in range(n - 1):  # L y = P b (unit lower)
            x = x - jnp.where(rows > k, a[:, k], 0.0)[:, None] * x[k][None, :]
        for k in reversed(range(n)):  # U x = y
            xk = x[k] / _safe(a[k, k])
            x = jnp.where((rows == k)[:, None], xk[None, :], x - jnp.where(rows < k, a[:, k], 0.0)[:, None] * xk[None, :])
    else:
        for k in range(n):  # U^T w = b (lower)
            xk = x[k] / _safe(a[k, k])
            x = jnp.where((rows == k)[:, None], xk[None, :], x - jnp.where(rows > k, a[k], 0.0)[:, None] * xk[None, :])
        for k in reversed(range(1, n)):  # L^T v = w (unit upper)
            x = x - jnp.where(rows < k, a[k], 0.0)[:, None] * x[k][None, :]
        # A permutation: unique indices, so that the solve can be transposed (reverse mode through it).
        x = jnp.zeros_like(x).at[lu.perm].set(x, unique_indices=True) if n > 1 else x
    return x[:, 0] if vector else x


@jax.custom_jvp
def factored_solve(matrix, lu: LU, rhs):
    """`matrix^-1 rhs` with `lu` the [`lu_factor`][] of `matrix`, differentiated through the solution.

    `d(A^-1 b) = A^-1 (db - dA x)` with the primal factors; the tangent of `lu` is ignored (it is that
    of `dA`). Differentiating the elimination instead costs a batched LU derivative per tangent under
    `jax.vmap`, and in reverse mode over forward mode (the second derivatives of the equations of motion
    that `jax.grad` through a Rosenbrock step and the discrete adjoint form) the transpose of the whole
    unrolled elimination. Linear in `rhs`, so it can be transposed. Forward mode over the transpose (a
    Hessian by `jax.jacfwd` of `jax.grad`) does not see this rule: it is exact only when `lu` is
    `lu_factor(matrix)` without `stop_gradient` (as in the equations of motion); with frozen factors
    (the Rosenbrock step, for speed) that route misses their dependence. (The factors are
    this module's, not `jax.scipy.linalg.lu_factor`'s, whose `lu_solve` turns the pivots into a
    permutation by a loop over the rows in every solve: at 61 unknowns more than the rest of a
    Rosenbrock step.)
    """
    return lu_solve(lu, rhs)


@factored_solve.defjvp
def _factored_solve_jvp(primals, tangents):
    matrix, lu, rhs = primals
    d_matrix, _, d_rhs = tangents
    x = lu_solve(lu, rhs)
    return x, lu_solve(lu, d_rhs - matmul(d_matrix, x))


def spd_solve(a, b):
    """`A^-1 b` for a symmetric positive definite `A` (Cholesky for `n > UNROLL_MAX`).

    Gauss–Jordan elimination without pivoting on `[A | b]`, one fused update per column; without
    pivoting it is stable for such matrices (the pivots are those of `A = L D L^T`).
    """
    n = a.shape[0]
    if n > UNROLL_MAX:
        return _cholesky_solve(a, b)
    vector = b.ndim == 1
    aug = jnp.concatenate([a, b[:, None] if vector else b], axis=1)
    unit = jnp.eye(n, dtype=aug.dtype)
    for k in range(n):
        row = aug[k] / aug[k, k]
        aug = aug - (aug[:, k] - unit[:, k])[:, None] * row[None, :]
    x = aug[:, n:]
    return x[:, 0] if vector else x


@jax.custom_jvp
def _cholesky_solve(a, b):
    """`A^-1 b` by LAPACK Cholesky, differentiated through the solution (one factorisation).

    `A` and its tangent are taken as symmetric (the factorisation reads one triangle), as the
    mass matrices passed here are.
    """
    return jsl.cho_solve(jsl.cho_factor(a), b)


@_cholesky_solve.defjvp
def _cholesky_solve_jvp(primals, tangents):
    # d(A^-1 b) = A^-1 (db - dA x), solved with the primal factor. Differentiating through the
    # factorisation instead costs a batched Cholesky derivative per tangent: under `jax.vmap` of the
    # tangents (a Jacobian by `jax.jacfwd`) XLA:CPU takes about 12 ms for 62 tangents at n = 30,
    # against 29 us this way.
    a, b = primals
    da, db = tangents
    factor = jsl.cho_factor(a)
    x = jsl.cho_solve(factor, b)
    return x, jsl.cho_solve(factor, db - da @ x)
