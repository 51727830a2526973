"""Guarded node relocation: move inner nodes of a quadrilateral mesh to raise its worst corner-Jacobian ratios.

gmsh's own smoothers (`Mesh.Smoothing`, `optimize("Laplace2D")`, `optimize("Relocate2D")`) move nodes towards the
mean of their neighbours whatever that does to the worst element, and leave ratios `min det J / max det J` near
0.07 next to curved boundaries of recombined and subdivided meshes. Here each node of an element below the
`target` ratio moves by a compass search that maximises the smallest ratio of the elements around it: a move is
taken only if it raises that smallest ratio, so no element ever gets worse than the worst one it touches was.
"""

import numpy as np

from .mesh import _corner_jacobians

# Compass directions of the search, and the halvings of its step before a node is left where it is.
_DIRECTIONS = np.stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)], axis=-1)
_HALVINGS = 8


def jacobian_ratios(xy: np.ndarray) -> np.ndarray:
    """`min det J / max det J` over the corners of quadrilaterals `(..., 4, 2)`, `(...)` (negative when folded)."""
    jac = _corner_jacobians(xy.reshape(-1, 4, 2)).reshape(xy.shape[:-1])  # it rolls along axis 1
    return jac.min(axis=-1) / np.maximum(jac.max(axis=-1), np.finfo(float).tiny)


def relocate_nodes(nodes: np.ndarray, elements: np.ndarray, movable: np.ndarray, target: float = 0.5,
                   passes: int = 4) -> np.ndarray:
    """Move the `movable` nodes of elements with a Jacobian ratio below `target` to raise the worst ratio around them.

    **Arguments:** `nodes` `(n_nodes, 2)`; `elements` `(n_elements, 4)` counter-clockwise; `movable` `(n_nodes,)`
    boolean (inner nodes: those on no curve of the geometry); `target`; `passes`, sweeps over the elements still
    below `target`.

    **Returns:** the new node coordinates `(n_nodes, 2)`; connectivity and the other nodes unchanged.
    """
    nodes = np.array(nodes, dtype=np.float64)
    order = np.argsort(elements.ravel(), kind="stable")
    starts = np.searchsorted(elements.ravel()[order], np.arange(nodes.shape[0] + 1))
    around = [order[starts[n]:starts[n + 1]] // 4 for n in range(nodes.shape[0])]  # elements at each node
    for _ in range(passes):
        low = np.flatnonzero(jacobian_ratios(nodes[elements]) < target)
        candidates = [n for n in np.unique(elements[low]) if movable[n]]
        moved = False
        for n in candidates:
            quads = elements[around[n]]
            at_n = quads == n
            corners = np.broadcast_to(nodes[quads], (len(_DIRECTIONS),) + quads.shape + (2,)).copy()
            point = nodes[n].copy()
            best = jacobian_ratios(nodes[quads]).min()
            step = 0.25 * np.mean(np.linalg.norm(nodes[quads] - point, axis=-1))
            for _ in range(_HALVINGS):
                trials = point + step * _DIRECTIONS
                corners[:, at_n] = trials[:, None]
                values = jacobian_ratios(corners).min(axis=1)  # the worst element around n, for each trial
                k = int(values.argmax())
                if values[k] > best:
                    point, best, moved = trials[k], values[k], True
                else:
                    step *= 0.5
            nodes[n] = point
        if not moved:
            break
    return nodes
