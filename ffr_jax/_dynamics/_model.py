"""Minimal-coordinate equations of motion by coordinate partitioning (paper eqs. 10–18).

The redundant coordinates `y_r` of a [`Scene`][] are split into independent `y` and dependent
`y_d` (paper eq. 10, `B` a permutation; in the plane `Z = I`, so `z_r = dy_r/dt`; a rigid spatial body's
velocities are the rates `(Rdot, pdot)` of its position and Euler parameters, so `Z = I` there too, see
`ffr_jax._spatial._rigid_body`). Given `(t, y, z)`:

1. `y_d` solves `c(B[y; y_d], t, p) = 0` by Newton's method, differentiated implicitly;
2. `z_d = -C_d^-1 (C_i z + c_t)` (velocity constraints, eq. 11);
3. `zdot_r = J zdot + gammabar_r` with `J = B[I; -C_d^-1 C_i]`, `gammabar_r = B[0; -C_d^-1 gamma]`
   and `gamma = (C z_r)_y z_r + 2 C_t z_r + c_tt` (eq. 13);
4. `Mbar zdot = J^T (h_a - M gammabar_r)` with `Mbar = J^T M J` (eqs. 15–18).
"""

import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import scipy.linalg

from .._errors import SimulationError, branched_error_if
from .._scene._scene import Scene
from ._small_linalg import block_lu_factor, factored_solve, lu_factor, lu_solve, matmul, spd_solve


class Partition(eqx.Module):
    """Static split of the redundant coordinates into independent and dependent ones (paper eq. 10)."""

    independent: tuple[int, ...] = eqx.field(static=True)
    dependent: tuple[int, ...] = eqx.field(static=True)

    @property
    def n_independent(self) -> int:
        return len(self.independent)


def choose_partition(scene: Scene, t0, y_r0, prefer_dependent: tuple[int, ...] = ()) -> Partition:
    """Choose the dependent coordinates from the constraint Jacobian at the initial state.

    QR factorisation with column pivoting of `C = dc/dy_r` (Wehage and Haug 1982) picks the
    `n_c` best-conditioned columns as dependent coordinates. Columns in `prefer_dependent` are
    tried first (e.g. rigid-body coordinates) when they alone have full rank.

    Raises `ValueError` when `C` does not have full row rank (redundant or contradictory
    constraints, or a singular initial configuration).
    """
    c = np.asarray(_constraint_jacobian(scene, jnp.asarray(t0, float), jnp.asarray(y_r0, float)))
    n_c, n = c.shape
    if n_c == 0:
        return Partition(independent=tuple(range(n)), dependent=())
    _, r, piv = scipy.linalg.qr(c, pivoting=True, mode="economic")
    diag = np.abs(np.diag(r))
    if diag.size < n_c or diag[-1] <= 1e-10 * max(diag[0], 1.0):
        raise ValueError(
            f"The constraint Jacobian at the initial state has rank below the number of constraints "
            f"({n_c}): the constraints are redundant or the initial configuration is singular "
            f"(singular values of C: {np.linalg.svd(c, compute_uv=False)})."
        )
    dependent = [int(i) for i in piv[:n_c]]
    if prefer_dependent and len(prefer_dependent) >= n_c:
        trial = list(prefer_dependent[:n_c])
        if np.linalg.matrix_rank(c[:, trial], tol=1e-8 * np.abs(c).max()) == n_c:
            dependent = trial
    dependent = tuple(sorted(dependent))
    independent = tuple(i for i in range(n) if i not in dependent)
    return Partition(independent=independent, dependent=dependent)


@eqx.filter_jit
def _constraint_jacobian(scene: Scene, t, y_r):
    return jax.jacfwd(scene.constraint_residual, argnums=1)(t, y_r)


def _zeros_for_none(primals, tangents):
    """Materialise symbolic-zero tangents (`None`) of inexact arrays as zeros."""
    return jtu.tree_map(
        lambda p, t: jnp.zeros_like(p) if (t is None and eqx.is_inexact_array(p)) else t,
        primals,
        tangents,
        is_leaf=lambda x: x is None,
    )


@functools.cache
def _runs(index: tuple[tuple[int, int], ...]) -> tuple[tuple[int, int, int], ...]:
    """Static slices `(source, start, stop)` whose concatenation is `[pieces[s][k] for s, k in index]`.

    Consecutive entries of one source become one slice, so that assembling and splitting
    coordinate vectors is a concatenation of slices (no gather or scatter).
    """
    runs: list[list[int]] = []
    for s, k in index:
        if runs and runs[-1][0] == s and runs[-1][2] == k:
            runs[-1][2] = k + 1
        else:
            runs.append([s, k, k + 1])
    return tuple(tuple(r) for r in runs)


def _gather_runs(pieces, runs):
    """Concatenate static slices of `pieces` along the leading axis (a gather without indices)."""
    parts = [pieces[s][a:b] for s, a, b in runs]
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=0)


class MinimalModel(eqx.Module):
    """Equations of motion of a [`Scene`][] in minimal coordinates `(y, z)` (paper eqs. 14–18).

    - `partition`: static split of the coordinates.
    - `dependent_guess`: `(t, y, scene) -> y_d` starting point of Newton's method (for loops a
      rigid-body estimate of the same assembly branch); default: `y_d` of the initial state.
    - `reference_dependent`: `y_d` at the initial state.
    - `newton_iterations`, `newton_tol`: at most this many iterations; converged when the update,
      or the error left after it as estimated from the contraction rate `theta` of the last two
      updates (`theta / (1 - theta) |update|`, for `theta < 1/2`), falls below
      `newton_tol * (1 + |y_d|)`.
    - `newton_unrolled`: the first iterations are unrolled (no loop), the rest run in a loop that
      stops at convergence. With a good `dependent_guess` Newton converges within the unrolled
      iterations and the loop ends at once; unrolled iterations after convergence only refine.
    - `reference_conditioning`: the Hadamard ratio [`hadamard_ratio`][] of `C_d` at the initial
      state (set by [`Problem`][]); along the motion a ratio below `DEAD_POINT_RATIO` times it
      (or below 1e-9 without a reference) is a dead point, an error. With `dependent_blocks`, the
      product of the diagonal blocks' ratios ([`block_hadamard_ratio`][]).
    - `dependent_blocks`: a static block lower-triangular structure of `C_d`, `((rows_k, cols_k), ...)`
      (constraint rows, positions in `y_d`; see `_block_triangular`), or `None` (one dense block).
      Newton's method then solves block after block, each with the earlier blocks' results, and the
      solves with `C_d` are block substitutions: the same `y_d` to round-off at a fraction of the cost
      of the dense system when a body's motion is prescribed (set by [`Problem`][]). Each block runs one
      unrolled Newton iteration, then the loop.
    """

    partition: Partition
    reference_dependent: jnp.ndarray
    reference_conditioning: jnp.ndarray | None = None
    dependent_guess: Callable | None = eqx.field(static=True, default=None)
    newton_iterations: int = eqx.field(static=True, default=25)
    newton_tol: float = eqx.field(static=True, default=1e-13)
    newton_unrolled: int = eqx.field(static=True, default=2)
    dependent_blocks: tuple | None = eqx.field(static=True, default=None)

    # --- coordinates -------------------------------------------------------------------------
    def _assemble_runs(self):
        n = len(self.partition.independent) + len(self.partition.dependent)
        source = [None] * n
        for k, i in enumerate(self.partition.independent):
            source[i] = (0, k)
        for k, i in enumerate(self.partition.dependent):
            source[i] = (1, k)
        return _runs(tuple(source))

    def assemble(self, y, y_d):
        """`y_r = B [y; y_d]` (along the leading axis; trailing axes are carried along)."""
        dtype = jnp.result_type(y, y_d)
        return _gather_runs((y.astype(dtype), y_d.astype(dtype)), self._assemble_runs())

    def split(self, v_r):
        """`v_r -> (v, v_d)`."""
        ind = _runs(tuple((0, i) for i in self.partition.independent))
        dep = _runs(tuple((0, i) for i in self.partition.dependent))
        empty = v_r[:0]
        return (_gather_runs((v_r,), ind) if ind else empty, _gather_runs((v_r,), dep) if dep else empty)

    # --- position level ----------------------------------------------------------------------
    def dependent_positions(self, t, y, scene: Scene):
        """`y_d(t, y, p)` solving `c(B[y; y_d], t, p) = 0` (Newton; implicit derivative)."""
        if not self.partition.dependent:
            return jnp.zeros((0,), y.dtype)
        return _solve_dependent(self, jnp.asarray(t, dtype=y.dtype), y, scene)

    def positions(self, t, y, scene: Scene):
        return self.assemble(y, self.dependent_positions(t, y, scene))

    # --- velocity and acceleration level -----------------------------------------------------
    def constraint_jacobian(self, t, y_r, scene: Scene):
        """`C = dc/dy_r`, `(n_c, n_r)`."""
        return jax.jacfwd(scene.constraint_residual, argnums=1)(t, y_r)

    def velocity_constraint(self, t, y_r, z_r, scene: Scene):
        """`cdot = C z_r + c_t` (paper eq. 11)."""
        return jax.jvp(scene.constraint_residual, (t, y_r), (jnp.ones_like(t), z_r))[1]

    def _velocity_level(self, t, y_r, scene: Scene):
        """`(C_i, c_t, LU of C_d)`: what the velocity and acceleration levels share."""
        c_t, c = jax.jacfwd(scene.constraint_residual, argnums=(0, 1))(t, y_r)
        c_i, c_d = self.split(c.T)
        return c_i.T, c_t, self.factor(c_d.T)

    def factor(self, c_d):
        """Factors of `C_d` `(n_c, n_d)` for [`lu_solve`][]: by its blocks where `dependent_blocks` is set."""
        return lu_factor(c_d) if self.dependent_blocks is None else block_lu_factor(c_d, self.dependent_blocks)

    def _dependent_velocities(self, z, c_i, c_t, lu):
        return -lu_solve(lu, matmul(c_i, z) + c_t)

    def velocities(self, t, y_r, z, scene: Scene):
        """`z_r = B [z; z_d]` with `z_d = -C_d^-1 (C_i z + c_t)`."""
        if not self.partition.dependent:
            return z
        c_i, c_t, lu = self._velocity_level(t, y_r, scene)
        return self.assemble(z, self._dependent_velocities(z, c_i, c_t, lu))

    def _minimal_terms(self, t, y_r, z_r, scene: Scene, c_i, lu):
        m = scene.mass_matrix(y_r)
        h = scene.applied_forces(t, y_r, z_r)
        if not self.partition.dependent:
            return m, h
        gamma = jax.jvp(
            lambda tt, yy: self.velocity_constraint(tt, yy, z_r, scene), (t, y_r), (jnp.ones_like(t), z_r)
        )[1]
        f = len(self.partition.independent)
        dep = -lu_solve(lu, jnp.concatenate([c_i, gamma[:, None]], axis=1))
        jac = self.assemble(jnp.eye(f, dtype=dep.dtype), dep[:, :f])  # J of eq. 13, (n_r, f)
        gamma_r = self.assemble(jnp.zeros(f, dep.dtype), dep[:, f])
        m_jac = matmul(m, jac)
        return matmul(jac.T, m_jac), matmul(jac.T, h) - matmul(m_jac.T, gamma_r)

    def minimal_terms(self, t, y_r, z_r, scene: Scene):
        """`(Mbar, fbar - gammabar)` of paper eq. 15 as functions of the redundant state.

        `Mbar = J^T M J` and `J^T (h_a - M gammabar_r)` with `J`, `gammabar_r` of eq. 13.
        """
        if not self.partition.dependent:
            return self._minimal_terms(t, y_r, z_r, scene, None, None)
        c_i, _, lu = self._velocity_level(t, y_r, scene)
        return self._minimal_terms(t, y_r, z_r, scene, c_i, lu)

    def accelerations(self, t, y_r, z_r, scene: Scene):
        """`zdot = Mbar^-1 (fbar - gammabar)` (paper eq. 15)."""
        mbar, rhs = self.minimal_terms(t, y_r, z_r, scene)
        return spd_solve(mbar, rhs)

    def state(self, t, y, z, scene: Scene):
        """Redundant positions and velocities `(y_r, z_r)` of the minimal state `(y, z)`."""
        y_r = self.positions(t, y, scene)
        return y_r, self.velocities(t, y_r, z, scene)

    def residual(self, t, y_r, z_r, zdot, scene: Scene):
        """`Mbar zdot - (fbar - gammabar)` (paper eq. 15) without forming `Mbar`: `J^T (M (J zdot +
        gammabar_r) - h_a)` with `J`, `gammabar_r` of eq. 13, by matrix-vector products only.

        Zero at the accelerations of a consistent state; its derivatives at fixed `zdot` give
        those of the accelerations (implicit function theorem, see [`state_and_accelerations`][])
        at `O(n^2)` per tangent instead of the `O(n^3)` of differentiating `J^T M J`.
        """
        m = scene.mass_matrix(y_r)
        h = scene.applied_forces(t, y_r, z_r)
        if not self.partition.dependent:
            return m @ zdot - h
        c_i, _, lu = self._velocity_level(t, y_r, scene)
        gamma = jax.jvp(
            lambda tt, yy: self.velocity_constraint(tt, yy, z_r, scene), (t, y_r), (jnp.ones_like(t), z_r)
        )[1]
        f = len(self.partition.independent)
        dep = -lu_solve(lu, jnp.concatenate([c_i, gamma[:, None]], axis=1))
        v = m @ self.assemble(zdot, dep[:, :f] @ zdot + dep[:, f]) - h
        v_i, v_d = self.split(v)
        return v_i + dep[:, :f].T @ v_d

    def state_and_accelerations(self, t, y, z, scene: Scene):
        """`(y_r, z_r, zdot)` at the minimal state `(y, z)`: [`state`][] and [`accelerations`][] in one
        pass that forms and factors the constraint Jacobian once.

        Differentiated through the equations of motion rather than through their solution: with
        `R(t, y_r, z_r, zdot, p)` the [`residual`][], `dzdot = -Mbar^-1 dR` at fixed `zdot`. On the
        reference case at 30 modes this halves the cost of a Jacobian by `jax.jacfwd`.
        """
        return _state_and_accelerations_once(self, jnp.asarray(t, dtype=jnp.result_type(y, float)), y, z, scene)

    def _state_and_accelerations(self, t, y, z, scene: Scene):
        y_r = self.positions(t, y, scene)
        if not self.partition.dependent:
            return y_r, z, spd_solve(*self._minimal_terms(t, y_r, z, scene, None, None))
        c_i, c_t, lu = self._velocity_level(t, y_r, scene)
        z_r = self.assemble(z, self._dependent_velocities(z, c_i, c_t, lu))
        mbar, rhs = self._minimal_terms(t, y_r, z_r, scene, c_i, lu)
        return y_r, z_r, spd_solve(mbar, rhs)

    def vector_field(self, t, y, z, scene: Scene):
        """`(ydot, zdot)` of the minimal equations of motion (paper eqs. 14–15)."""
        return z, self.state_and_accelerations(t, y, z, scene)[2]


# A dead point is where C_d (the constraint Jacobian with respect to the dependent coordinates)
# is singular: there the constraints have a double root, which Newton's method approaches only
# linearly and stalls ~sqrt(eps) ~ 1e-8 (relative) away from, with a residual at round-off level.
# The test is on the Hadamard ratio of C_d relative to its value at the start (scale-free, and free
# of the units of the coordinates). Measured on the slider-crank family (4 x 2 and 12 x 2 rods, the
# crank at full speed; benchmarks/RESULTS.md, "Bad input"): regular motions keep the ratio above 0.2
# (eccentricity 0.98 l) and above 6e-3 for a rigid rod at 0.99999 l; a flexible rod pulled through
# the dead point drops below 1e-5 within a few steps of approaching it, then the step size collapses
# to 1e-15 s while the ratio stalls at 1e-8..3e-9 (before this test, the step budget ran out there).
# 1e-5 sits between the two by three decades each way.
DEAD_POINT_RATIO = 1e-5

_SINGULAR = (
    "Dead point: the coordinate partition became singular along the motion. The constraint Jacobian "
    "with respect to the dependent coordinates, C_d, lost rank (its Hadamard ratio |det C_d| / prod |rows| "
    "fell below 1e-5 of its value at the start): the mechanism reached a configuration where the "
    "dependent coordinates are no function of the independent ones (e.g. a slider-crank whose rod "
    "stands upright because the crank eccentricity is too close to the rod length, or a flexible rod "
    "compressed through that position). Change the geometry (for the slider-crank an eccentricity well "
    "below the rod length, e.g. <= 0.98 l), choose another partition (Problem(partition=...)), or end the "
    "simulation before that time."
)
_NOT_CONVERGED = (
    "Newton's method for the dependent coordinates did not converge: the position constraints "
    "have no solution near the starting guess (the mechanism cannot assemble, or the guess is "
    "on another branch). Check the scene geometry or give a better dependent_guess."
)


def _newton(model: MinimalModel, t, y, scene: Scene):
    """Primal Newton iteration for `y_d`, with convergence and regularity checks.

    With `model.dependent_blocks`, block after block: block `k`'s rows are solved for its coordinates with the
    earlier blocks' results in place (the later blocks' coordinates do not enter them)."""
    guess = model.reference_dependent if model.dependent_guess is None else model.dependent_guess(t, y, scene)
    guess = jnp.asarray(guess, dtype=y.dtype)

    def residual(y_d):
        return scene.constraint_residual(t, model.assemble(y, y_d))

    if model.dependent_blocks is None:
        y_d, hadamard = _newton_block(model, residual, guess)
    else:
        blocks = model.dependent_blocks
        values = [guess[np.asarray(cols)] for _, cols in blocks]
        runs = _runs(tuple(sorted(((k, i) for k, (_, cols) in enumerate(blocks) for i in range(len(cols))),
                                  key=lambda ki: blocks[ki[0]][1][ki[1]])))
        hadamard = jnp.ones((), y.dtype)
        for k, (rows, _) in enumerate(blocks):
            def block_residual(x, k=k, rows=rows):
                y_r = model.assemble(y, _gather_runs(values[:k] + [x] + values[k + 1:], runs))
                return _rows_residual(scene, t, y_r, rows)

            values[k], ratio = _newton_block(model, block_residual, values[k], unrolled=1)
            hadamard = hadamard * ratio
        y_d = _gather_runs(values, runs)
    # Regularity is judged at the last Newton step. A blown-up or NaN run is a convergence failure,
    # not a singular partition: NaN fails `hadamard <= ...` and the residual test below catches it.
    scale = 1.0 + jnp.max(jnp.abs(model.assemble(y, y_d)))
    singular = hadamard <= 1e-9
    if model.reference_conditioning is not None:
        singular = singular | (hadamard <= DEAD_POINT_RATIO * model.reference_conditioning)
    not_converged = ~(jnp.max(jnp.abs(residual(y_d))) <= 1e-9 * scale)
    return branched_error_if(
        y_d, singular | not_converged, jnp.where(singular, 0, 1), (_SINGULAR, _NOT_CONVERGED), SimulationError
    )


def _rows_residual(scene: Scene, t, y_r, rows: tuple[int, ...]):
    """Rows `rows` of `c(y_r, t, p)`, evaluating only the constraints that own them."""
    starts = np.cumsum([0] + [c.n_equations for c in scene.constraints])
    owners = sorted({int(np.searchsorted(starts, r, side="right")) - 1 for r in rows})
    local = np.concatenate([np.arange(starts[k], starts[k + 1]) for k in owners])
    values = jnp.concatenate([scene.constraints[k].residual(t, y_r, scene) for k in owners])
    position = {int(r): i for i, r in enumerate(local)}
    return _gather_runs((values,), _runs(tuple((0, position[r]) for r in rows)))


def _newton_block(model: MinimalModel, residual, guess, unrolled: int | None = None):
    """Newton's method on `residual(x) = 0` from `guess`: `(x, Hadamard ratio of the Jacobian at the last step)`.

    `unrolled` iterations (default `model.newton_unrolled`) before the loop. Blocks take one: a block of a prescribed
    motion (a driven crank) is often solved exactly by the guess, and there a second unrolled iteration per block
    costs more than the loop's convergence test (spatial slider-crank forward run 181 -> 127 ms CPU,
    benchmarks/RESULTS.md, "Spatial slider-crank (issue 26)")."""
    def iterate(x):
        """One Newton step, and the Hadamard ratio `|det C_d| / prod |rows of C_d|` where it was taken."""
        res, jac = residual(x), jax.jacfwd(residual)(x)
        lu = lu_factor(jac)
        step = lu_solve(lu, res)
        hadamard = jnp.abs(lu.det()) / jnp.maximum(jnp.prod(jnp.linalg.norm(jac, axis=1)), 1e-300)
        return x - step, jnp.max(jnp.abs(step)), hadamard

    def converged(x, size, previous):
        # The step size, or the error left after it estimated from the contraction rate
        # theta = |step_k| / |step_k-1| (Hairer and Wanner, Sect. IV.8): theta / (1 - theta) |step_k|.
        theta = size / previous
        left = jnp.where((theta < 0.5) & jnp.isfinite(previous), theta / (1.0 - theta) * size, size)
        return left <= model.newton_tol * (1.0 + jnp.max(jnp.abs(x)))

    unrolled = max(1, min(model.newton_unrolled if unrolled is None else unrolled, model.newton_iterations))
    x, size = guess, jnp.asarray(jnp.inf, guess.dtype)
    for _ in range(unrolled):
        previous = size
        x, size, hadamard = iterate(x)
    if model.newton_iterations > unrolled:
        def body(carry):
            x, size, _, _, k = carry
            x, new_size, hadamard = iterate(x)
            return x, new_size, size, hadamard, k + 1

        def cond(carry):
            x, size, previous, _, k = carry
            return (k < model.newton_iterations) & ~converged(x, size, previous)

        x, size, _, hadamard, _ = jax.lax.while_loop(cond, body, (x, size, previous, hadamard, unrolled))
    return x, hadamard


def block_hadamard_ratio(matrix, blocks) -> float:
    """The product of the [`hadamard_ratio`][]s of the diagonal blocks `matrix[rows_k][:, cols_k]` (NumPy); that of
    `matrix` for `blocks=None`: the conditioning that Newton's method by blocks reports."""
    if blocks is None:
        return hadamard_ratio(matrix)
    matrix = np.asarray(matrix, dtype=float)
    return float(np.prod([hadamard_ratio(matrix[np.ix_(rows, cols)]) for rows, cols in blocks]))


def hadamard_ratio(matrix) -> float:
    """`|det A| / prod_i |row_i(A)|` in `[0, 1]` of a square matrix (NumPy): 1 for orthogonal rows, 0 when singular;
    unchanged by scaling a row."""
    matrix = np.asarray(matrix, dtype=float)
    norms = np.prod(np.linalg.norm(matrix, axis=1))
    return float(abs(np.linalg.det(matrix)) / norms) if norms > 0 else 0.0


@eqx.filter_custom_jvp
def _solve_dependent(model, t, y, scene):
    return _newton(model, t, y, scene)


@_solve_dependent.def_jvp
def _solve_dependent_jvp(primals, tangents):
    model, t, y, scene = primals
    _, dt, dy, dscene = _zeros_for_none(primals, tangents)
    # The primal through the custom rule itself, not `_newton`: when this rule is differentiated
    # again (reverse mode through a solver that linearises the vector field, e.g. a Rosenbrock
    # method under `jax.grad`), the Newton while-loop would otherwise be transposed, which JAX
    # cannot do; through the rule, the second derivative is again a linear solve.
    y_d = _solve_dependent(model, t, y, scene)

    def residual(t_, y_, scene_):
        return scene_.constraint_residual(t_, model.assemble(y_, y_d))

    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    ddyn, _ = eqx.partition(dscene, eqx.is_inexact_array)
    _, dres = jax.jvp(
        lambda t_, y_, dyn_: residual(t_, y_, eqx.combine(dyn_, static)), (t, y, dyn), (dt, dy, ddyn)
    )
    c_d = jax.jacfwd(lambda yd: scene.constraint_residual(t, model.assemble(y, yd)))(y_d)
    return y_d, -lu_solve(model.factor(c_d), dres)


@eqx.filter_custom_jvp
def _state_and_accelerations(model, t, y, z, scene):
    return model._state_and_accelerations(t, y, z, scene)


@_state_and_accelerations.def_jvp
def _state_and_accelerations_jvp(primals, tangents):
    model, t, y, z, scene = primals
    if all(leaf is None for leaf in jtu.tree_leaves(tangents[4], is_leaf=lambda x: x is None)):
        # No scene tangent (a Jacobian with respect to the state, as a Rosenbrock step forms): the
        # scene stays a constant of the linearisation. Materialised zero tangents of its body
        # data would be carried through every product of the equations of motion, for each
        # tangent: at 30 modes that made a Jacobian by `jax.jacfwd` four times as costly.
        _, dt, dy, dz = _zeros_for_none(primals[:4], tangents[:4])
        return _state_and_accelerations_tangents(model, t, y, z, scene, dt, dy, dz, None)
    _, dt, dy, dz, dscene = _zeros_for_none(primals, tangents)
    return _state_and_accelerations_tangents(model, t, y, z, scene, dt, dy, dz, dscene)


# Traced once per structure and shapes, then reused: a Rosenbrock step and its transposition, the adjoint's
# products and diffrax's own evaluations call the equations of motion many times under several transformations,
# and inside a jit boundary JAX keeps one trace and one JVP, linearisation or batch of it per use. XLA inlines
# the calls again, so the compiled program, and its numbers, are those without it (the README mechanism's
# first gradient, tracing 24-30 -> 10 s on one core; benchmarks/RESULTS.md, "Where a first call's time goes").
_state_and_accelerations_once = eqx.filter_jit(_state_and_accelerations)


def _state_and_accelerations_tangents(model, t, y, z, scene, dt, dy, dz, dscene):
    """Primal and tangent of `(y_r, z_r, zdot)`; `dscene=None`: the scene held fixed."""
    dyn, static = eqx.partition(scene, eqx.is_inexact_array)
    if dscene is None:
        def state(t_, y_, z_):
            return model.state(t_, y_, z_, scene)

        def residual_at(zdot):
            return lambda t_, a, b: model.residual(t_, a, b, zdot, scene)

        extra, d_extra = (), ()
    else:
        ddyn, _ = eqx.partition(dscene, eqx.is_inexact_array)

        def state(t_, y_, z_, dyn_):
            return model.state(t_, y_, z_, eqx.combine(dyn_, static))

        def residual_at(zdot):
            return lambda t_, a, b, d: model.residual(t_, a, b, zdot, eqx.combine(d, static))

        extra, d_extra = (dyn,), (ddyn,)

    (y_r, z_r), (dy_r, dz_r) = jax.jvp(state, (t, y, z, *extra), (dt, dy, dz, *d_extra))
    mbar, rhs = model.minimal_terms(t, y_r, z_r, scene)
    zdot = spd_solve(mbar, rhs)
    d_residual = jax.jvp(residual_at(zdot), (t, y_r, z_r, *extra), (dt, dy_r, dz_r, *d_extra))[1]
    # The tangent solve must be linear in `d_residual` for reverse mode (transposition): `lu_solve`
    # is, the augmented elimination of `spd_solve` is not. Differentiated again (the discrete adjoint's
    # second derivatives, `jax.grad` through a Rosenbrock solve), it is differentiated through its
    # solution, not through the elimination (`factored_solve`).
    lu = lu_factor(mbar)
    return (y_r, z_r, zdot), (dy_r, dz_r, -factored_solve(mbar, lu, d_residual))
