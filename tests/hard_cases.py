"""The hard members of the slider–crank family (issue 6) and the checks run on them.

Shared by `tests/test_hard_cases.py` (small, fast members) and `benchmarks/bench_hard_cases.py`
(the whole table, slow members included), so that both check exactly the same thing.

Compilation dominates the cost of a gradient on a small case (tens of seconds per method, a
fraction of a second per run), and it depends only on the *structure* of a case: mesh size,
number of modes, time span, partition. [`variant`][] therefore builds a case with other array
values (crank radius, crank speed, initial state) inside the static structure of a base case, so
that one compiled gradient serves every variant of the same size.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
from helpers import ATOL, FD_ATOL, FD_RTOL, RTOL, adjoint_value_and_grad, central_difference, tight_objective  # noqa: F401

import ffr_jax

# The compiled programs (`adjoint_value_and_grad`, `tight_objective`) live in `helpers.py`, shared
# with the other test modules; the finite-difference evaluations run at FD_RTOL = 1e-12, two
# decades below the gradient's forward tolerance (1e-10), so that the difference quotient is not
# dominated by solver noise.


def variant(base: ffr_jax.Case, other: ffr_jax.Case) -> ffr_jax.Case:
    """The array values of `other` (crank radius and law, initial state, templates) in the static
    structure of `base`, so that functions compiled for `base` run `other` without recompiling.

    Raises `ValueError` when the two differ in anything but array values that matters: array
    shapes, the coordinate partition, the time span, the mesh or the number of modes.
    """
    for name in ("n_modes", "t0", "t1", "jump_ts"):
        if getattr(base, name) != getattr(other, name):
            raise ValueError(f"variant: {name} differs ({getattr(base, name)} vs {getattr(other, name)}).")
    if base.mesh != other.mesh or base.model.partition != other.model.partition:
        raise ValueError("variant: the mesh or the coordinate partition differs; build a separate case.")
    base_leaves, treedef = jax.tree_util.tree_flatten(eqx.filter(base, eqx.is_array))
    other_leaves = jax.tree_util.tree_leaves(eqx.filter(other, eqx.is_array))
    if [a.shape for a in base_leaves] != [b.shape for b in other_leaves]:
        raise ValueError("variant: array shapes differ; build a separate case.")
    arrays = jax.tree_util.tree_unflatten(treedef, other_leaves)
    return eqx.combine(arrays, eqx.filter(base, eqx.is_array, inverse=True))


# --- designs ---------------------------------------------------------------------------------------


def _free_eigenpairs(case, x):
    k, m = (np.asarray(a) for a in case.fe_matrices(jnp.asarray(x)))
    free = np.setdiff1d(np.arange(case.mesh.n_dof), case.fixed_dofs)
    lam, vec = scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)])
    full = np.zeros((case.mesh.n_dof, lam.size))
    full[free] = vec
    return lam, full


def _is_axial(case, mode) -> bool:
    """Whether a mode of a design symmetric about the rod's mid-line is symmetric (axial) rather
    than antisymmetric (bending): `u_x` mirrored across the mid-line keeps its sign."""
    mesh = case.mesh
    ux = mode[0::2].reshape(mesh.nx + 1, mesh.ny + 1)
    return np.linalg.norm(ux - ux[:, ::-1]) < np.linalg.norm(ux + ux[:, ::-1])


def crossing_design(case, low: float = 0.2, high: float = 0.95, tol: float = 1e-13):
    """A design whose first axial eigenvalue equals a bending eigenvalue inside the retained set.

    The family `x(s) = (1 - s) 0.5 + s ramp`, with `ramp` rising linearly along the rod from
    `low` at A to `high` at B and equal rows (symmetric about the mid-line), lowers the first
    axial frequency through a bending one; symmetric and antisymmetric modes do not interact, so
    the two eigenvalues truly cross (no veering). Bisection on `s` finds the crossing.

    **Returns:** `(x, gap)`, the design and the relative gap of the crossing pair there, and the
    index `(k, k+1)` of the pair in the retained set.
    """
    columns = np.linspace(0.0, 1.0, case.mesh.nx - 2)
    ramp = low + (high - low) * columns

    def design(s):
        return np.tile((1 - s) * 0.5 + s * ramp, case.mesh.ny)

    def axial_index(s):
        lam, vec = _free_eigenpairs(case, design(s))
        axial = [k for k in range(case.n_modes + 1) if _is_axial(case, vec[:, k])]
        if not axial:
            raise ValueError("crossing_design: no axial mode among the lowest n_modes + 1 for this case.")
        return lam, axial[0]

    lo, hi = 0.0, 1.0
    start, end = axial_index(lo)[1], axial_index(hi)[1]
    if end >= start:
        raise ValueError("crossing_design: the axial eigenvalue does not move down through a bending one.")
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if axial_index(mid)[1] == start:
            lo = mid
        else:
            hi = mid
    lam, a = axial_index(lo)
    pair = (a - 1, a)
    if pair[1] >= case.n_modes:
        raise ValueError(f"crossing_design: the crossing pair {pair} is not inside the {case.n_modes} retained modes.")
    gap = (lam[pair[1]] - lam[pair[0]]) / lam[pair[1]]
    return jnp.asarray(design(lo)), gap, pair


def void_design(case, seed: int = 0):
    """A design with void elements at `x_min` next to solid ones (`x = 1`) and intermediate ones.

    Over the middle half of the rod the inner rows are void and the outer rows solid (the layout
    an optimum tends to, REFERENCE_CASE §4); with two rows, the lower row is void there and the
    upper one solid. Elsewhere the design is random in `[0.3, 0.9]`. Element density and
    stiffness contrasts reach `rho(x_min) / rho0 = c x_min^q ~ 1e-7` and `E(x_min) / E0 = 1e-6`.
    """
    mesh, x_min = case.mesh, case.material.x_min
    grid = np.random.default_rng(seed).uniform(0.3, 0.9, (mesh.ny, mesh.nx - 2))
    cols = np.arange(mesh.nx - 2)
    middle = np.abs(cols - (mesh.nx - 3) / 2) <= (mesh.nx - 2) / 4
    if mesh.ny == 2:
        grid[0, middle], grid[1, middle] = x_min, 1.0
    else:
        inner = np.zeros(mesh.ny, bool)
        inner[1:-1] = True
        grid[np.ix_(inner, middle)] = x_min
        grid[np.ix_(~inner, middle)] = 1.0
    return jnp.asarray(grid.ravel())


# --- checks ----------------------------------------------------------------------------------------


def one_sided_difference(f, h: float):
    """Second-order one-sided difference at 0 into `+h` (for a design variable sitting at `x_min`)."""
    return (-3 * f(0.0) + 4 * f(h) - f(2 * h)) / (2 * h)


def gradient_checks(case, x, grad, *, n_directions: int = 1, n_entries: int = 1, step: float = 1e-4,
                    seed: int = 0, one_sided_step: float = 1e-4, batched: bool = False):
    """Finite-difference counterparts of `grad`: directional derivatives and single entries.

    Directions are random unit vectors over the entries that lie at least `2 step` inside
    `[x_min, 1]` and away from the SIMP switch at `0.1`; the first entry at `x_min`, if any, is
    checked with the one-sided difference. The largest `|grad|` entry is always among the checked
    entries. With `psi` evaluated at rtol 1e-12 and `step = 1e-4`, truncation (`step^4`) and
    solver noise (`1e-12 / step`) stay near 1e-8 relative. The one-sided step at `x_min` is 1e-4, the
    largest that keeps truncation negligible: the second-order formula's truncation is about
    `(step / x_min)^2 = 1e-4` of the entry (SIMP's `x^6` mass law, `x_min = 0.01`), while its solver
    noise, `8 e / (2 step)` for psi evaluations good to `e`, falls as the step grows. On the 48 x 4
    void design the entry at `x_min` (6.6e-8, against max |grad| 1.55e-3) came out -4.2e-8 with a step
    of 1e-6, -2.8e-7 with 1e-7, and -6.56e-8 and -6.84e-8 in two runs with 1e-5 (2.3e-9 off: 1.5e-6 of
    max |grad|, over the agreement bound): noise, shrinking 10x at 1e-4.

    `batched=True` evaluates every `psi` the differences need as one `jax.vmap` of the tight objective
    ([`tight_objectives`][]): the same solves, each with its own adaptive steps at rtol 1e-12, so the same
    values up to round-off and the same bounds; one compiled program and one pass through the time steps
    instead of one run per evaluation (the long horizon's eight 30-s solves).

    **Returns:** a list of `(what, adjoint value, finite-difference value)`.
    """
    x = jnp.asarray(x)
    xn = np.asarray(x)
    x_min = case.material.x_min
    interior = (xn - 2 * step > x_min) & (xn + 2 * step <= 1.0) & (np.abs(xn - 0.1) > 2 * step)
    at_min = xn == x_min
    rng = np.random.default_rng(seed)
    g = np.asarray(grad)

    # (what, adjoint value, direction, difference formula, its step): the formulas' evaluations are collected
    # first, so that they can run as one batch.
    wanted = []
    for k in range(n_directions):
        v = rng.normal(size=xn.size) * interior
        v /= np.linalg.norm(v)
        wanted.append((f"direction {k}", float(g @ v), v, central_difference, step))
    largest = int(np.argmax(np.abs(g) * interior))
    others = rng.permutation(np.setdiff1d(np.flatnonzero(interior), [largest]))
    entries = [largest] + [int(i) for i in others[: n_entries - 1]]
    for i in entries:
        wanted.append((f"entry {i}", float(g[i]), np.eye(xn.size)[i], central_difference, step))
    for i in np.flatnonzero(at_min)[:1]:
        wanted.append((f"entry {i} at x_min", float(g[i]), np.eye(xn.size)[i], one_sided_difference, one_sided_step))

    # Each formula's arguments s, recorded by calling it once on a recorder, then evaluated at x + s v.
    points = []
    for _, _, v, formula, h in wanted:
        formula(lambda s, v=v: points.append((s, v)) or 0.0, h)
    designs = [x + s * jnp.asarray(v) for s, v in points]
    if batched:
        values = [float(p) for p in tight_objectives(case, jnp.stack(designs))]
    else:
        values = [float(tight_objective(case, y)) for y in designs]
    values = iter(values)
    return [(what, a, formula(lambda s: next(values), h)) for what, a, _, formula, h in wanted]


# XLA options for programs whose run time, not their compile, is the cost (the long horizon's 30-s solves): the
# suite compiles with LLVM at -O0 (tests/conftest.py: compiles dominate it), which ran the 30-s adjoint gradient in
# 29.7 s and one tight 30-s solve in 8.3 s; at XLA's default level 2 they run in 15.9 s and 5.1 s for 2-3 s more
# compile each (one core, quiet machine). Numbers differ by round-off only, which no tolerance here depends on.
RUN_TIME_OPTIONS = {"xla_backend_optimization_level": 2, "xla_llvm_disable_expensive_passes": False}


@eqx.filter_jit(compiler_options=RUN_TIME_OPTIONS)
def tight_objectives(case, xs):
    """`psi` at each row of `xs` (`(k, n_design)`) at the finite differences' tolerances (rtol 1e-12), one
    vmapped program: each row's solve takes its own adaptive steps, as `tight_objective` alone would
    (compiled for run time: `RUN_TIME_OPTIONS`)."""
    return jax.vmap(lambda y: ffr_jax.objective(case, y, rtol=FD_RTOL, atol=FD_ATOL))(xs)


@eqx.filter_jit(compiler_options=RUN_TIME_OPTIONS)
def adjoint_value_and_grad_for_run_time(case, x):
    """`helpers.adjoint_value_and_grad` (the same call, the same settings) compiled with `RUN_TIME_OPTIONS`: for a
    case of its own structure whose solves, not its compile, are the cost (it shares no program with others)."""
    return ffr_jax.value_and_grad(case, x, "adjoint", rtol=RTOL, atol=ATOL)


def agreement(grad, checks) -> float:
    """Largest `|adjoint - finite difference|` over the checks, relative to `max |grad|`."""
    scale = float(np.max(np.abs(np.asarray(grad))))
    return max(abs(a - b) for _, a, b in checks) / scale
