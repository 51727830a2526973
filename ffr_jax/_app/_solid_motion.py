"""The motion of a designed solid body: node positions of its rigid placement and elastic displacements in 3-D."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics._case import Case
from .._dynamics._simulate import solve_minimal
from .._spatial._euler_parameters import rotation_matrix


def solid_body_motion(case: Case, x_phys, ts, *, rtol: float = 1e-8, atol: float = 1e-12):
    """The motion of the case's designed solid body at times `ts`: node positions with and without elasticity.

    Simulates the case for the physical densities `x_phys` (output at `ts`) and returns, per time, the rigid
    placement `R + A(p) c_n` of every node `n` (`c_n` its body-frame coordinates, `A(p)` the rotation of the Euler
    parameters `p`) and its elastic displacement `A(p) Phi_n q` in the inertial frame, with the modes the simulation
    used. The spatial counterpart of the planar `body_motion`.

    **Returns:** `(rigid, elastic, y_r)`: `(n_t, n_nodes, 3)`, `(n_t, n_nodes, 3)` and `(n_t, n_r)`.
    """
    x_phys = case.design.check(jnp.asarray(x_phys, dtype=float))
    rigid, elastic, y_r = _solid_motion(case, x_phys, jnp.asarray(ts, dtype=float), rtol, atol)
    return np.asarray(rigid), np.asarray(elastic), np.asarray(y_r)


@eqx.filter_jit
def _solid_motion(case: Case, x_phys, ts, rtol: float, atol: float):
    problem = case.problem_for(x_phys)
    scene = problem.scene
    n_nodes = case.mesh.n_nodes
    modes = case.design.eigenpairs(x_phys)[1].reshape(n_nodes, 3, -1)
    trajectory = solve_minimal(problem.model, scene, problem.t0, problem.t1, problem.y0, problem.z0, ts=ts, rtol=rtol,
                               atol=atol, jump_ts=problem.jump_ts, dt0=problem.dt0)
    offset = scene.offsets[scene.body_index(case.design_map.name)]
    nodes = jnp.asarray(case.mesh.nodes)

    def place(y):
        r, p, q = y[offset:offset + 3], y[offset + 3:offset + 7], y[offset + 7:offset + 7 + modes.shape[2]]
        rotation = rotation_matrix(p)
        return r + nodes @ rotation.T, (modes @ q) @ rotation.T

    rigid, elastic = jax.vmap(place)(trajectory.positions)
    return rigid, elastic, trajectory.positions
