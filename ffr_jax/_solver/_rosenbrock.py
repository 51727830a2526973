"""Linearly implicit Rosenbrock methods as diffrax solvers: the abstract base and its dense output.

A Rosenbrock method replaces the nonlinear stage equations of an implicit Runge–Kutta method by
one linear solve per stage with the Jacobian of the vector field at the start of the step. For
`y' = f(t, y)` and a step `t0 -> t0 + h` (Hairer and Wanner 1996, Sect. IV.7, eq. 7.4', in the
form of the Rodas codes):

`(I / (h gamma) - J) k_i = f(t0 + c_i h, y0 + sum_j a_ij k_j) + h d_i f_t + sum_j (C_ij / h) k_j`,

`y1 = y0 + sum_i b_i k_i`, with `J = f_y(t0, y0)`, `f_t = f_t(t0, y0)`. One Jacobian, one LU
factorisation and `s` right-hand sides per step; no Newton iteration, hence no convergence
failure and no root-finder tolerance. Stiffly accurate, L-stable methods (Rodas) damp
components with `h |lambda| >> 1` instead of resolving them.

Inside diffrax the vector field is only known as `g(t, y) = f(t, y) h` (`term.vf_prod` with the
control `h = t1 - t0`), so the stages are solved multiplied by `h`:
`(I / gamma - g_y) k_i = g(t_i, u_i) + h d_i g_t + sum_j C_ij k_j`.
The state may be any pytree of float arrays; it is flattened for the linear algebra.
"""

import abc
import dataclasses
from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._dynamics._small_linalg import factored_solve, lu_factor


@dataclasses.dataclass(frozen=True)
class RosenbrockTableau:
    """Coefficients of an `s`-stage Rosenbrock method in the Rodas form (module docstring).

    - `gamma`: the diagonal coefficient; `a`, `c_coupling`: strictly lower `(s, s)` matrices of
      the stage points and of the `C_ij / h` couplings; `c`: `(s,)` stage times; `d`: `(s,)`
      coefficients of `h f_t`.
    - `b`: `(s,)` weights of the solution; `b_error`: `(s,)` weights of the error estimate
      (solution minus embedded solution).
    - `dense`: `(r, s)`: the dense output `y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta)
      (K_1 + theta (K_2 + ... theta K_r)))` with `K_m = sum_j dense[m, j] k_j`.
    - `order`, `embedded_order`, `dense_order`: classical orders of the solution, the embedded
      solution and the dense output (its local error is `O(h^(dense_order + 1))`).
    """

    gamma: float
    a: np.ndarray
    c_coupling: np.ndarray
    c: np.ndarray
    d: np.ndarray
    b: np.ndarray
    b_error: np.ndarray
    dense: np.ndarray
    order: int
    embedded_order: int
    dense_order: int

    def __post_init__(self):
        s = self.c.shape[0]
        for name in ("a", "c_coupling"):
            m = getattr(self, name)
            assert m.shape == (s, s) and np.all(np.triu(m) == 0), name
        assert self.d.shape == self.b.shape == self.b_error.shape == (s,)
        assert self.dense.ndim == 2 and self.dense.shape[1] == s

    @property
    def stages(self) -> int:
        return self.c.shape[0]


def stiffly_accurate_rows(a_rows, s: int):
    """The `(s, s)` matrix `a` and weights `b` of a Rodas method from its first explicit stage rows.

    Rodas methods are stiffly accurate: after the last stage point `u = y0 + sum_j a_mj k_j`
    (given row `m`), every further stage is taken at the previous point plus the previous
    stage, `u_{i+1} = u_i + k_i`, and `y1 = u_s + k_s` (Hairer and Wanner 1996, Sect. VI.4).
    """
    a = np.zeros((s, s))
    for i, row in enumerate(a_rows, start=1):
        a[i, : len(row)] = row
    m = len(a_rows)
    for i in range(m + 1, s):
        a[i] = a[i - 1]
        a[i, i - 1] = 1.0
    b = a[s - 1].copy()
    b[s - 1] = 1.0
    b_error = np.zeros(s)
    b_error[s - 1] = 1.0
    return a, b, b_error


def lower(rows, s: int):
    """A strictly lower `(s, s)` matrix from its rows 2..s."""
    out = np.zeros((s, s))
    for i, row in enumerate(rows, start=1):
        out[i, : len(row)] = row
    return out


def rosenbrock_matrix(tab: RosenbrockTableau, g, t0, u0):
    """`(g0, g_t, matrix)` at the start of a Rosenbrock step: `g(t0, u0)`, `dg/dt` and `I / gamma - dg/du`.

    One `jax.linearize` of `g` and a `vmap` of its linear map over the `n + 1` unit tangents.
    """
    n, dtype = u0.shape[0], u0.dtype
    g0, linear = jax.linearize(g, t0, u0)
    tangents_t = jnp.zeros(n + 1, jnp.result_type(t0)).at[n].set(1.0)
    tangents_u = jnp.concatenate([jnp.eye(n, dtype=dtype), jnp.zeros((1, n), dtype)])
    columns = jax.vmap(linear)(tangents_t, tangents_u)  # (n + 1, n)
    return g0, columns[n], jnp.eye(n, dtype=dtype) / tab.gamma - columns[:n].T


def rosenbrock_stages(tab: RosenbrockTableau, g, t0, h, u0, g0, g_t, matrix, lu):
    """The `(s, n)` stages `k_i` of one Rosenbrock step (module docstring) for `g(t, u) = h f(t, u)`.

    `g0 = g(t0, u0)`, `g_t = dg/dt(t0, u0)`, `matrix = I / gamma - dg/du(t0, u0)` and `lu` its
    factors (see [`lu_factor`][ffr_jax._small_linalg.lu_factor]). Stage 1 reuses `g0`; stages 2..s
    run in one scan, so `g` is traced (and compiled) twice rather than `s` times.
    """
    s, n, dtype = tab.stages, u0.shape[0], u0.dtype
    a = jnp.asarray(tab.a, dtype)
    coupling = jnp.asarray(tab.c_coupling, dtype)
    ks = jnp.zeros((s, n), dtype).at[0].set(factored_solve(matrix, lu, g0 + (tab.d[0] * h) * g_t))

    def stage(ks, coefficients):
        i, a_i, coupling_i, c_i, d_i = coefficients
        gi = g(t0 + c_i * h, u0 + a_i @ ks)
        return ks.at[i].set(factored_solve(matrix, lu, gi + (d_i * h) * g_t + coupling_i @ ks)), None

    ks, _ = jax.lax.scan(stage, ks, (jnp.arange(1, s), a[1:], coupling[1:], jnp.asarray(tab.c[1:], dtype),
                                     jnp.asarray(tab.d[1:], dtype)))
    return ks


class RosenbrockInterpolation(diffrax.AbstractLocalInterpolation):
    """The continuous output of a Rodas method on one step (see [`RosenbrockTableau`][])."""

    t0: jax.Array
    t1: jax.Array
    y0: object
    y1: object
    k: object  # like y0 with a leading axis of the r dense coefficients

    def evaluate(self, t0, t1=None, left: bool = True):
        del left
        if t1 is not None:
            return jtu.tree_map(lambda a, b: a - b, self.evaluate(t1), self.evaluate(t0))
        theta = (t0 - self.t0) / (self.t1 - self.t0)

        def one(y0, y1, k):
            inner = k[-1]
            for m in range(k.shape[0] - 2, -1, -1):
                inner = k[m] + theta * inner
            return (1 - theta) * y0 + theta * (y1 + (1 - theta) * inner)

        return jtu.tree_map(one, self.y0, self.y1, self.k)


class AbstractRosenbrock(diffrax.AbstractAdaptiveSolver):
    """A Rosenbrock method for stiff ODEs as a diffrax solver (module docstring).

    Each step forms the Jacobian `g_y` and `g_t` of the vector field at the start of the step by
    one `jax.linearize` and a `vmap` of its linear map over the `n + 1` unit tangents (`n` the
    size of the flattened state), factors `I / gamma - g_y` once (LU) and solves `s` stages.
    The error estimate is the tableau's embedded difference; the dense output its own
    interpolant (order 3 or 4 for the Rodas methods).

    Works with every diffrax adjoint (`RecursiveCheckpointAdjoint`, `BacksolveAdjoint`,
    `ForwardMode`): the step is a composition of differentiable JAX operations.
    """

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.AbstractLocalInterpolation]] = RosenbrockInterpolation
    tableau: eqx.AbstractClassVar[RosenbrockTableau]

    def order(self, terms):
        return self.tableau.order

    def error_order(self, terms):
        # Local error of the embedded difference: O(h^(embedded_order + 1)).
        return self.tableau.embedded_order + 1

    def init(self, terms, t0, t1, y0, args):
        return None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        tab = self.tableau
        u0, unravel = jax.flatten_util.ravel_pytree(y0)
        dtype = u0.dtype
        control = terms.contr(t0, t1)
        h = t1 - t0

        def g(t, u):
            return jax.flatten_util.ravel_pytree(terms.vf_prod(t, unravel(u), args, control))[0]

        g0, g_t, matrix = rosenbrock_matrix(tab, g, t0, u0)
        # Factors held constant: `factored_solve` differentiates the solves through `matrix` either way, and
        # with differentiable factors `jax.grad` through this solver ran slower (30 modes, rtol 1e-6: 6.3 s
        # against 5.3 s). So forward mode over reverse mode through a step (a Hessian of psi by `jax.jacfwd`
        # of `jax.grad` through this solver) misses the factors' dependence on the state: not supported.
        lu = lu_factor(jax.lax.stop_gradient(matrix))

        ks = rosenbrock_stages(tab, g, t0, h, u0, g0, g_t, matrix, lu)
        u1 = u0 + jnp.asarray(tab.b, dtype) @ ks
        err = jnp.asarray(tab.b_error, dtype) @ ks
        dense = jnp.asarray(tab.dense, dtype) @ ks  # (r, n)
        y1 = unravel(u1)
        k_tree = jax.vmap(unravel)(dense)
        dense_info = dict(y0=y0, y1=y1, k=k_tree)
        return y1, unravel(err), dense_info, None, diffrax.RESULTS.successful
