"""Block lower-triangular structure of the constraint Jacobian of the dependent coordinates, found at build time.

`C_d = dc/dy_d` of many scenes permutes to block lower-triangular form: a driven body's rotation follows from its
driver and hinge alone, its position then from the hinge, and only then do the closed loops couple the rest (the
spatial slider–crank: the crank's Euler parameters 4 x 4, its position 3 x 3, the rod 7 x 7). Newton's method and the
solves with `C_d` then run block by block, each block with the results of the earlier ones: smaller systems, and no
work on the coupling of a block with the later ones (it is zero).

The structure is that of the functions, not of one state: it is read from the sparsity pattern of `C_d` at the initial
state and at random states and random scene parameters around it (an entry zero at all of them is taken as zero
everywhere; one that is zero only by the values of this state or design, e.g. a hinge marker at a body's origin, is
nonzero at the random parameters). The blocks are the strongly connected components of the pattern's graph under a
perfect matching of rows to columns (the Dulmage–Mendelsohn fine decomposition of a square matrix, Duff and Reid
1978), in an order in which every block depends only on earlier ones.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from .._scene._scene import Scene
from ._small_linalg import UNROLL_MAX

Blocks = tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]

# The random states and scene parameters that the pattern is read at (besides the initial state): two, so that an
# entry would have to vanish at three unrelated points to be missed.
_SAMPLES = 2


@eqx.filter_jit
def _jacobian(scene: Scene, t, y_r):
    return jax.jacfwd(scene.constraint_residual, argnums=1)(t, y_r)


def _perturbed(tree, rng, scale: float):
    """`tree` with every inexact array leaf moved randomly: relatively by `scale` and absolutely by `scale` times its
    largest entry (so that zero entries move too)."""
    def move(leaf):
        if not eqx.is_inexact_array(leaf):
            return leaf
        a = np.asarray(leaf)
        size = max(float(np.max(np.abs(a), initial=0.0)), 1.0)
        return jnp.asarray(a * (1.0 + scale * rng.standard_normal(a.shape)) + scale * size * rng.standard_normal(a.shape),
                           dtype=leaf.dtype)
    return jax.tree_util.tree_map(move, tree)


def constraint_pattern(scene: Scene, t0: float, y_r0, dependent: tuple[int, ...], seed: int = 0) -> np.ndarray:
    """Boolean `(n_c, n_d)` sparsity pattern of `C_d` (entries nonzero or not finite at any of the states read)."""
    rng = np.random.default_rng(seed)
    y_r0 = np.asarray(y_r0, dtype=float)
    cols = list(dependent)
    pattern = None
    for k in range(_SAMPLES + 1):
        if k == 0:
            s, t, y = scene, t0, y_r0
        else:
            s = _perturbed(scene, rng, 0.1)
            t = t0 + rng.uniform(0.0, 1.0)
            y = y_r0 + 0.1 * (1.0 + np.abs(y_r0)) * rng.standard_normal(y_r0.shape)
        c = np.asarray(_jacobian(s, jnp.asarray(t, float), jnp.asarray(y)))[:, cols]
        nonzero = (c != 0.0) | ~np.isfinite(c)
        pattern = nonzero if pattern is None else pattern | nonzero
    return pattern


def _ordered_components(pattern: np.ndarray, row_of: dict[int, int]) -> list[list[list[int]]]:
    """Strongly connected components of the rows' graph (row `i` -> row `j` when row `i` has an entry in the column
    matched to row `j`) by level: level 0 needs no other component, level `l` only components of lower levels."""
    n = pattern.shape[0]
    edges = [{row_of[int(c)] for c in np.flatnonzero(pattern[i])} - {i} for i in range(n)]
    graph = scipy.sparse.csr_matrix(
        (np.ones(sum(len(e) for e in edges)), ([i for i, e in enumerate(edges) for _ in e],
                                              [j for e in edges for j in sorted(e)])), shape=(n, n))
    count, labels = scipy.sparse.csgraph.connected_components(graph, directed=True, connection="strong")
    needs = [set() for _ in range(count)]
    for i, e in enumerate(edges):
        needs[labels[i]].update(int(labels[j]) for j in e if labels[j] != labels[i])
    level: dict[int, int] = {}
    while len(level) < count:
        for k in range(count):
            if k not in level and all(j in level for j in needs[k]):
                level[k] = 1 + max((level[j] for j in needs[k]), default=-1)
    return [[[int(i) for i in np.flatnonzero(labels == k)] for k in range(count) if level[k] == lev]
            for lev in range(max(level.values()) + 1)]


def block_structure(pattern: np.ndarray) -> Blocks | None:
    """`((rows_k, cols_k), ...)`: a block lower-triangular form of a square pattern (block `k` has no entries in the
    columns of later blocks), or `None` when there is only one block or the pattern is structurally singular."""
    pattern = np.asarray(pattern, dtype=bool)
    n = pattern.shape[0]
    if pattern.shape != (n, n) or n < 2:
        return None
    match = scipy.sparse.csgraph.maximum_bipartite_matching(scipy.sparse.csr_matrix(pattern), perm_type="column")
    if np.any(match < 0):
        return None
    row_of = {int(c): r for r, c in enumerate(match)}
    # Components of one level do not depend on each other: one block each level, as long as it stays a small dense
    # solve (their Jacobian is block diagonal, and one unrolled or closed-form solve of the union costs less than
    # one per component).
    blocks = []
    for level in _ordered_components(pattern, row_of):
        merged: list[int] = []
        for rows in level:
            if merged and len(merged) + len(rows) > UNROLL_MAX:
                blocks.append(merged)
                merged = []
            merged = merged + rows
        blocks.append(merged)
    if len(blocks) < 2:
        return None
    return tuple((tuple(sorted(rows)), tuple(sorted(int(match[r]) for r in rows))) for rows in blocks)


def dependent_blocks(scene: Scene, t0: float, y_r0, dependent: tuple[int, ...]) -> Blocks | None:
    """The static block lower-triangular structure of `C_d` of `scene` (rows: constraint rows, columns: positions in
    the dependent coordinates), or `None` for one block."""
    if len(dependent) < 2 or scene.n_constraints != len(dependent):
        return None
    return block_structure(constraint_pattern(scene, t0, y_r0, dependent))
