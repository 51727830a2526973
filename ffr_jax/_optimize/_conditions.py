"""Several operating conditions of one design case, evaluated as one batched (`vmap`) solve."""

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .. import _api
from .._dynamics._case import Case
from .._design.design_map import DesignMap
from .._dynamics._problem import Problem
from .._scene._stiffening import GeometricStiffening
from .._spatial._stiffening import SpatialGeometricStiffening
from .._sensitivity._base import AbstractSensitivity
from .._typing import Designs

COMBINE = ("weighted", "worst")


class OperatingConditions(eqx.Module):
    """One design under several operating conditions: `psi(x) = sum_k w_k psi_k(x)` or `max_k psi_k(x)`.

    The conditions are cases of one mechanism that differ only in the values of their arrays —
    the crank speed of `slider_crank(speed=...)`, a load, a spring constant, the initial state
    — not in their structure (the same design map, bodies, joints, objective terms, `t0`, `t1`
    and breakpoints). Their problems are stacked along a leading axis, and one evaluation

    1. maps the design to the designed bodies' data once, `p(x)` (FE model and modal reduction),
    2. solves the `K` motions and their sensitivities as **one batched solve** (`jax.vmap` over
       the conditions: the `K` step-size controllers run side by side in one loop),
    3. combines the scene gradients, `sum_k w_k dpsi_k/dp` (or the worst condition's), and pulls
       them back through `p(x)` with **one** VJP of the design map.

    `"weighted"`: `psi = sum_k w_k psi_k`, the exact gradient. `"worst"`: `psi = max_k psi_k`
    with the gradient of the condition that attains it (a subgradient where two coincide; a
    gradient method may then zig-zag between conditions, and MMA's bound formulation — one
    [`FunctionConstraint`][] per condition — is the smooth alternative).

    **Arguments:**
    - `cases`: two or more [`Case`][]s of the same structure (e.g. `[slider_crank(speed=8 pi),
      slider_crank(speed=12 pi)]`); the first one's design map is used.
    - `weights`: `(K,)` non-negative weights of `"weighted"` (default `1 / K` each).
    - `combine`: `"weighted"` or `"worst"`.

    Use it as the case of [`make_objective`][] (`fj.make_objective(conditions, filter=...)`) or
    directly through [`OperatingConditions.value_and_grad`][].
    """

    case: Case
    problems: Problem
    weights: Float[Array, " K"]
    worst: Bool[Array, ""]  # an array, not a static flag: both combinations share one compiled program
    n_conditions: int = eqx.field(static=True)

    def __init__(self, cases: Sequence[Case], weights=None, combine: str = "weighted"):
        cases = list(cases)
        if len(cases) < 2 or not all(isinstance(c, Case) for c in cases):
            raise ValueError("OperatingConditions takes a list of two or more cases (ffr_jax.Case), got "
                             f"{[type(c).__name__ for c in cases]}.")
        if combine not in COMBINE:
            raise ValueError(f"combine must be one of {COMBINE}, got {combine!r}.")
        if not isinstance(cases[0].design_map, DesignMap):
            raise ValueError("OperatingConditions needs cases with an ffr_jax.DesignMap.")
        dynamic0, static0 = eqx.partition(cases[0].problem, eqx.is_array)
        dynamics = [dynamic0]
        for k, case in enumerate(cases[1:], start=1):
            if not bool(eqx.tree_equal(case.design_map, cases[0].design_map)):
                raise ValueError(f"Condition {k} designs other bodies than condition 0 (its design map differs); "
                                 "the conditions must share one design.")
            dynamic, static = eqx.partition(case.problem, eqx.is_array)
            if jax.tree.structure(dynamic) != jax.tree.structure(dynamic0) or not eqx.tree_equal(static, static0):
                raise ValueError(
                    f"Condition {k} differs from condition 0 in its structure (bodies, joints, objective terms, "
                    "t0, t1, the laws' breakpoints or other static settings), not only in array values; conditions "
                    "evaluated as one batched solve may differ only in numbers such as the crank speed or a load."
                )
            shapes = [(a.shape, a.dtype) for a in jax.tree.leaves(dynamic)]
            if shapes != [(a.shape, a.dtype) for a in jax.tree.leaves(dynamic0)]:
                raise ValueError(f"Condition {k} has arrays of other shapes than condition 0 (e.g. another mesh or "
                                 "number of modes); the conditions must share one design.")
            dynamics.append(dynamic)
        n = len(cases)
        if weights is None:
            weights = np.full(n, 1.0 / n)
        weights = np.asarray(weights, dtype=float)
        if weights.shape != (n,) or not np.all(np.isfinite(weights)) or np.any(weights < 0) or not weights.sum() > 0:
            raise ValueError(f"weights must be {n} finite non-negative numbers, not all zero; got {weights}.")
        self.case = cases[0]
        self.problems = eqx.combine(jax.tree.map(lambda *a: jnp.stack(a), *dynamics), static0)
        self.weights = jnp.asarray(weights)
        self.worst = jnp.asarray(combine == "worst")
        self.n_conditions = n

    @property
    def combine(self) -> str:
        return "worst" if bool(self.worst) else "weighted"

    def value_and_grad(self, x: Designs, method: str | AbstractSensitivity = "adjoint", *, rtol: float = 1e-10,
                       atol: float = 1e-12, solver=None, max_steps: int = 200_000):
        """`(psi, dpsi/dx, psi_k)`: the combined objective, its gradient (shaped like `x`) and the
        `(K,)` objectives of the conditions. Traceable (it runs inside the optimizer's compiled step)."""
        method = _api.sensitivity_method(method)
        return _values_and_grad(self, x, method, rtol, atol, solver, max_steps)


def _designed_nodes(case: Case):
    """`where(scene)`: the nodes of a scene that the design map writes (the designed bodies' data and their
    geometric stiffness), in a fixed order."""
    scene = case.problem.scene
    bodies = [scene.body_index(name) for name in case.design_map.names]
    forces = [k for k, force in enumerate(scene.forces)
              if isinstance(force, (GeometricStiffening, SpatialGeometricStiffening)) and force.body in bodies]
    return lambda s: tuple(s.bodies[i].data for i in bodies) + tuple(s.forces[k].modal_geometric_stiffness
                                                                     for k in forces)


def _values_and_grad(conditions: OperatingConditions, x, method, rtol, atol, solver, max_steps):
    case = conditions.case
    where = _designed_nodes(case)
    scene_x, pullback = eqx.filter_vjp(case.scene, case.check(x))  # FE + modes once, for every condition
    designed = where(scene_x)

    def one(problem):
        scene = eqx.tree_at(where, problem.scene, designed)
        return method.value_and_grad_scene(problem, scene, rtol=rtol, atol=atol, solver=solver,
                                           max_steps=max_steps)

    psis, g_scenes = eqx.filter_vmap(one)(conditions.problems)
    # weighted: w; worst: the indicator of the largest psi_k (the first of equal ones)
    weights = jnp.where(conditions.worst, jax.nn.one_hot(jnp.argmax(psis), psis.shape[0], dtype=psis.dtype),
                        conditions.weights)
    value = jnp.dot(weights, psis)
    g_scene = jax.tree.map(lambda g: jnp.tensordot(weights, g, axes=1), g_scenes)
    # Only the designed nodes depend on x, and they are the same in every condition's scene: the
    # combined cotangent pulled back through p(x) once is sum_k w_k dpsi_k/dx.
    (g_x,) = pullback(g_scene)
    return value, g_x, psis
