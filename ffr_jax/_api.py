"""Top-level functions: simulate a problem, its objective and its gradient by any sensitivity method.

Each public function runs a module-level `equinox.filter_jit` program, so that it is compiled on
its first call and reused for equal array shapes and static settings (like `diffrax.diffeqsolve`):
calling `value_and_grad(case, x)` again with another design of the same shape does not recompile.
So there is no need to wrap them in `jax.jit`; inside a larger compiled function of your own, see
[`clean_errors`][] for how errors raised at run time read.

Every public function checks its options (tolerances, step budget) before anything is traced, and
a concrete design's values before the compiled program runs (a [`DesignError`][] at once); values
known only inside the program (a design under `jax.vmap`, a dead point along the motion) raise
there, and reach the caller as the package's [`DesignError`][] or [`SimulationError`][] with the
message first ([`clean_errors`][]).
"""

import time
import warnings

import diffrax
import equinox as eqx
import jax
import numpy as np

from . import _checks
from ._dynamics._case import Case
from ._compiled import Program, logger
from ._errors import clean_errors
from ._dynamics._problem import Problem, check_scene_data
from ._scene._scene import Scene
from ._sensitivity._adjoint import Adjoint
from ._sensitivity._autodiff import Autodiff
from ._sensitivity._backsolve import Backsolve
from ._sensitivity._base import AbstractSensitivity
from ._sensitivity._direct import Direct
from ._sensitivity._discrete_adjoint import DiscreteAdjoint
from ._sensitivity._finite_differences import FiniteDifferences
from ._sensitivity._cached import (Uncacheable, _scene_of, cache_directory, cacheable, cached_value_and_grad,
                                  kept_call, use_persistent_cache)
from ._sensitivity._check import GradientCheck, compare_with_differences
from ._sensitivity._route import choose_route
from ._dynamics._simulate import Trajectory, simulate as simulate_redundant, solve_minimal
from ._typing import DesignsInput


METHODS = {
    "adjoint": Adjoint,
    "autodiff": Autodiff,
    "backsolve": Backsolve,
    "discrete-adjoint": DiscreteAdjoint,
    "direct": Direct,
    "fd": FiniteDifferences,
}


def sensitivity_method(method: str | AbstractSensitivity) -> AbstractSensitivity:
    """Map a method name (`"adjoint"`, `"autodiff"`, `"backsolve"`, `"direct"`, `"fd"`, `"discrete-adjoint"`) to its object."""
    if isinstance(method, AbstractSensitivity):
        return method
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"Unknown sensitivity method {method!r}; choose one of {sorted(METHODS)} "
                         "or pass an AbstractSensitivity instance (e.g. ffr_jax.Adjoint(rtol=1e-9)).")
    return METHODS[method]()


def _problem_and_method(target, x, method):
    """`(problem, method)` for a problem target, where `x` may carry the method positionally."""
    if x is not None:
        if isinstance(x, (str, AbstractSensitivity)):
            method = x
        else:
            raise ValueError("A Problem has no design vector: call value_and_grad(problem, method=...), or build "
                             "a Case (problem + design map) to differentiate with respect to a design.")
    return target, sensitivity_method(method)


def _check_target(target) -> None:
    if not isinstance(target, (Case, Problem)):
        raise ValueError(f"Expected an ffr_jax.Problem or a case (e.g. ffr_jax.cases.slider_crank()), "
                         f"got {type(target).__name__}.")
    if isinstance(target, Problem):  # data edited with eqx.tree_at after the problem was built (issue 32)
        check_scene_data(target.scene)


def _check_ts(ts) -> None:
    """Output times, where known on the host: finite and non-decreasing."""
    if ts is None or _checks.is_traced(ts):
        return
    values = np.asarray(ts, dtype=float)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"ffr_jax.simulate: the output times ts must be finite, got {values}.")
    if np.any(np.diff(values) < 0):
        raise ValueError("ffr_jax.simulate: the output times ts must be non-decreasing.")


def _check_options(where: str, rtol, atol, max_steps) -> None:
    """The solve options of a public function, before anything is traced (and float64 on: issue 32)."""
    _checks.float64_on(where)
    _checks.tolerances(rtol, atol, where)
    _checks.max_steps(max_steps, where)


def _design(case: Case, x, where: str):
    """The design of a case, checked before the simulation is traced where its values are known.

    A concrete design is checked on the host at once. A traced one goes through a small compiled
    check first: under `jax.vmap` its values are known, so a bad batch fails there without
    compiling the simulation; under a user's `jax.jit` the check becomes part of the program.
    The simulation program checks the design again (it may be called on its own).
    """
    if x is None:
        raise ValueError(f"{where}(case, x): a case needs its design x (e.g. case.initial_design(0.5)).")
    return _checked_design(case, x) if _checks.is_traced(x) else case.check(x)


@eqx.filter_jit
def _checked_design(case, x):
    return case.check(x)


# --- compiled programs ------------------------------------------------------------------------
def _simulate_problem_fn(problem, solver, rtol, atol, ts, dense, max_steps, adjoint, dt0):
    obj = problem.objective
    return solve_minimal(
        problem.model, problem.scene, problem.t0, problem.t1, problem.y0, problem.z0,
        integrand=obj.integrand, terminal=obj.terminal, solver=solver, rtol=rtol, atol=atol, ts=ts, dense=dense,
        max_steps=max_steps, adjoint=adjoint, jump_ts=problem.jump_ts, dt0=problem.dt0 if dt0 is None else dt0,
    )


def _simulate_case_fn(case, x, solver, rtol, atol, ts, dense, max_steps, adjoint):
    return _simulate_problem_fn(case.problem_for(case.check(x)), solver, rtol, atol, ts, dense, max_steps, adjoint, None)


def _objective_problem_fn(problem, solver, rtol, atol, max_steps):
    return _simulate_problem_fn(problem, solver, rtol, atol, None, False, max_steps, None, None).psi


def _shape_of(leaf):
    return jax.ShapeDtypeStruct(leaf.shape, leaf.dtype)


def _scalar_like(problem):
    """A float scalar of the problem's dtype, by its shape (psi)."""
    return jax.ShapeDtypeStruct((), problem.y0.dtype)


def _kept(function, args, what: str, plain, out_like=None):
    """`function(*args)` through a program kept between processes (`_sensitivity/_cached.py`) where the cache
    is on and the arguments are concrete and keyable, else `plain()` (the in-process compiled program)."""
    traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(args))
    directory = None if traced else cache_directory()
    if directory is not None:
        use_persistent_cache(directory)
        out = kept_call(function, args, directory, what, out_like)
        if out is not None:
            return out
    return plain()


def _value_and_grad_problem_fn(problem, method, rtol, atol, solver, max_steps):
    return method.value_and_grad_problem(problem, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps)


def _value_and_grad_design_fn(case, x, method, rtol, atol, solver, max_steps):
    return method.value_and_grad_design(case, case.check(x), rtol=rtol, atol=atol, solver=solver, max_steps=max_steps)


def _value_and_grad_scene_fn(problem, scene, method, rtol, atol, solver, max_steps):
    return method.value_and_grad_scene(problem, scene, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps)


_simulate_problem = Program(_simulate_problem_fn, "the simulation of a problem")
_simulate_case = Program(_simulate_case_fn, "the simulation of a case")
_value_and_grad_problem = Program(_value_and_grad_problem_fn, "the gradient of a problem")
_value_and_grad_design = Program(_value_and_grad_design_fn, "the design gradient of a case")
_value_and_grad_scene = Program(_value_and_grad_scene_fn, "the scene gradient of a problem")


def _cached(case, x, method, rtol, atol, solver, max_steps, directory, detail):
    """The design gradient through programs a later process loads instead of compiling (see
    `_sensitivity/_cached.py`), or `None` where the program has no key that identifies it across
    processes; says once per process what compiling or loading took."""
    use_persistent_cache(directory)
    start = time.perf_counter()
    try:
        (psi, grad), program, fresh = cached_value_and_grad(case, x, method, rtol=rtol, atol=atol, solver=solver,
                                                            max_steps=max_steps, export_dir=directory / "programs")
    except Uncacheable:
        return None
    if fresh:
        how = ("loaded from the cache (compiled by an earlier process)" if program.loaded else
               "compiled (first call for these shapes and settings; kept for later processes)")
        logger.info("the design gradient of a case (%s) %s in %.1f s, with its first run %.1f s; cache: %s", detail,
                    how, program.seconds, time.perf_counter() - start, directory)
    return psi, grad


def _route(target, method, solver, rtol, atol):
    """`(method, solver, rtol, atol, detail)` of a gradient: the default route where no method (and no
    solver) is given ([`choose_route`][]), else the given method with the paper's tolerances."""
    if method is None and solver is None:
        route = choose_route(target)
        logger.debug("value_and_grad: %s", route.reason)
        method, solver, detail = route.method, route.solver, route.reason
        default_rtol, default_atol = route.rtol, route.atol
    else:
        method = sensitivity_method("adjoint" if method is None else method)
        detail, default_rtol, default_atol = type(method).__name__, 1e-10, 1e-12
    if rtol is None:
        rtol, atol = default_rtol, default_atol if atol is None else atol
    elif atol is None:
        atol = rtol / 100
    return method, solver, rtol, atol, detail


# --- public functions -------------------------------------------------------------------------
@clean_errors
def simulate(target, x=None, *_legacy, solver: diffrax.AbstractSolver | None = None,
             rtol: float = 1e-10, atol: float = 1e-12, ts=None, dense: bool = False, max_steps: int = 1_000_000,
             adjoint: diffrax.AbstractAdjoint | None = None, dt0: float | None = None, **_legacy_kwargs) -> Trajectory:
    """Simulate a [`Problem`][ffr_jax.Problem], or a case at design `x`: `simulate(problem)`,
    `simulate(case, x)`.

    **Arguments:**
    - `target`: a [`Problem`][ffr_jax.Problem], or a case; `x`: the case's design (an array, or a dict of
      arrays by body; not for a problem).
    - `solver`: any diffrax solver (default `Dopri8()`: the retained modes make the equations
      mildly stiff; on the reference case explicit 5th-order `Tsit5()` needs about 18,000 steps at
      every rtol from 1e-6 to 1e-9, its stability limit, Dopri8 4,700-6,400; benchmarks/RESULTS.md).
    - `rtol`, `atol`: step-size control tolerances (default: the paper's 1e-10 / 1e-12).
    - `ts`: output times (default: `t1` only); `dense`: keep the dense interpolant.
    - `max_steps`: diffrax step budget; `adjoint`: diffrax adjoint for differentiating through it;
      `dt0`: the first step (problems only; default: diffrax's estimate).

    **Returns:** a [`Trajectory`][ffr_jax.Trajectory] with the independent and all redundant
    coordinates and velocities at the output times, and `psi`.

    **Example:**
    ```python
    import ffr_jax as fj
    case = fj.cases.slider_crank(12, 2, 6, 0.3)
    trajectory = fj.simulate(case, case.initial_design(0.5), ts=jnp.linspace(0.0, 0.3, 31))
    print(trajectory.psi, trajectory.positions.shape)
    ```
    """
    _check_options("ffr_jax.simulate", rtol, atol, max_steps)
    _check_ts(ts)
    if isinstance(target, (Problem, Case)) and (_legacy or _legacy_kwargs):
        raise ValueError("simulate(problem) and simulate(case, x) take only keyword options (solver, rtol, atol, ts, "
                         "dense, max_steps, adjoint, dt0).")
    if isinstance(target, Problem):
        _check_target(target)
        if x is not None:
            raise ValueError("simulate(problem, ...) takes no design: a problem's parameters are in its scene "
                             "(simulate(case, x) simulates a case at design x).")
        return _simulate_problem(target, solver, rtol, atol, ts, dense, max_steps, adjoint, dt0)
    if isinstance(target, Case):
        if x is None:
            raise ValueError("simulate(case, x): give the case's design x (e.g. case.initial_design(0.5)).")
        return _simulate_case(target, _design(target, x, "simulate"), solver, rtol, atol, ts, dense, max_steps,
                              adjoint)
    if _legacy or _legacy_kwargs:  # simulate(model, scene, t0, t1, y_r0, z_r0, integrand=..., jump_ts=...)
        warnings.warn("simulate(model, scene, t0, t1, y_r0, z_r0, ...) is deprecated and will be removed in the next "
                      "release; build a ffr_jax.Problem from the scene and call simulate(problem).",
                      DeprecationWarning, stacklevel=3)
        return simulate_redundant(target, x, *_legacy, solver=solver, rtol=rtol, atol=atol, ts=ts, dense=dense,
                                  max_steps=max_steps, adjoint=adjoint, dt0=dt0, **_legacy_kwargs)
    raise ValueError(f"simulate: the target must be a ffr_jax.Problem or a case (e.g. ffr_jax.cases.slider_crank()), "
                     f"got {type(target).__name__}.")


@clean_errors
def simulate_case(case: Case, x: DesignsInput, *, rtol: float = 1e-10, atol: float = 1e-12,
                  solver: diffrax.AbstractSolver | None = None, ts=None, dense: bool = False,
                  max_steps: int = 1_000_000, adjoint: diffrax.AbstractAdjoint | None = None) -> Trajectory:
    """Deprecated: `simulate(case, x)`."""
    warnings.warn("ffr_jax.simulate_case is deprecated and will be removed in the next release; use "
                  "ffr_jax.simulate(case, x).", DeprecationWarning, stacklevel=3)
    _check_options("ffr_jax.simulate_case", rtol, atol, max_steps)
    return _simulate_case(case, _design(case, x, "simulate_case"), solver, rtol, atol, ts, dense, max_steps, adjoint)


@clean_errors
def objective(target, x: DesignsInput | None = None, *, rtol: float = 1e-10, atol: float = 1e-12,
              solver: diffrax.AbstractSolver | None = None, max_steps: int = 1_000_000):
    """`psi = G(t1) + int_{t0}^{t1} F dt` of a problem, or of a case at design `x`
    (REFERENCE_CASE §4: the integral compliance of the rod).

    **Arguments:**
    - `target`: a [`Problem`][], or a case such as `ffr_jax.cases.slider_crank()` with `x`, its
      `(n_design,)` densities in `[x_min, 1]`.
    - `rtol`, `atol`: forward tolerances (the paper's 1e-10 / 1e-12 by default).
    - `solver`: diffrax solver (default `Dopri8()`, see [`simulate`][]).

    **Returns:** scalar `psi`.
    """
    _check_target(target)
    _check_options("ffr_jax.objective", rtol, atol, max_steps)
    if isinstance(target, Problem):
        if x is not None:
            raise ValueError("A Problem has no design vector: call objective(problem).")
        return _kept(_objective_problem_fn, (target, solver, rtol, atol, max_steps), "the objective of a problem",
                     lambda: _simulate_problem(target, solver, rtol, atol, None, False, max_steps, None, None).psi,
                     out_like=_scalar_like(target))
    x = _design(target, x, "objective")

    def plain():  # one program, the FE stage and the solve (the in-process path)
        return _simulate_case(target, x, solver, rtol, atol, None, False, max_steps, None).psi

    # Kept between processes as two programs split at the scene, as the design gradient is: the FE stage (loaded
    # where it can be exported; with SciPy's Lanczos modes, a host callback, compiled in every process) and the solve
    # (exported, then loaded). One program with the FE stage inside was compiled whole in every process wherever the
    # FE stage has callbacks: the reference case's second process 6.8 -> 2.1 s, its first call 8.9 -> 6.9 s (one core;
    # benchmarks/RESULTS.md, "Compile time per public entry point"). The same psi, all digits printed.
    # The FE stage is the design gradient's own (`_scene_of`, the same key): one kept program for both.
    scene = _kept(_scene_of, (target, x), "the FE stage of a case", lambda: None)
    if scene is None:  # the cache is off, or the case has no key (e.g. a lambda in it)
        return plain()
    problem = target.problem.with_scene(scene)
    return _kept(_objective_problem_fn, (problem, solver, rtol, atol, max_steps), "the objective of a case (its solve)",
                 plain, out_like=_scalar_like(problem))


@clean_errors
def value_and_grad(target, x: DesignsInput | None = None, method: str | AbstractSensitivity | None = None, *,
                   rtol: float | None = None, atol: float | None = None, solver: diffrax.AbstractSolver | None = None,
                   max_steps: int = 200_000, check: bool = False):
    """`(psi, grad psi)` of a case with respect to its design, or of a problem with respect to its arrays.

    **Arguments:**
    - `target`: a case such as `ffr_jax.cases.slider_crank()` followed by `x`, its designs: a
      dict `{body name: (n_design_b,) densities}` in `[x_min, 1]`, or a flat `(n_design,)` array
      when the case designs one body; or a [`Problem`][] (no `x`).
    - `method`: `None` (default): the route [`choose_route`][] picks from the retained frequencies and
      the time span — the discrete adjoint of Rodas5P at rtol 1e-6 / atol 2e-9 (documented accuracy 1e-6
      of the largest entry) where an explicit solver would sit at its stability limit (the reference
      case: 1.2 s on one core, 7.6e-8 of the largest entry from a tight reference), else the paper's
      adjoint with Dopri8 at rtol 1e-10; the route is named in
      the first call's compile message on the `"ffr_jax"` logger (INFO). Or `"adjoint"` (the paper's adjoint variable method), `"autodiff"`
      (`jax.grad` through diffrax), `"backsolve"` (diffrax `BacksolveAdjoint`), `"direct"`
      (forward sensitivities), `"fd"` (central differences, designs only), `"discrete-adjoint"`
      (the discrete adjoint of a Rosenbrock forward solve, `ffr_jax.DiscreteAdjoint`: the derivative
      of the computed psi at about half the cost of autodiff through it; `solver` defaults to
      `ffr_jax.Rodas5P()` for it), or a configured method object such as
      `ffr_jax.Adjoint(rtol=1e-9, atol=1e-11)` or `ffr_jax.FiniteDifferences(step=1e-4)`.
    - `rtol`, `atol`: forward tolerances (default: the route's with `method=None`, else the paper's
      1e-10 / 1e-12; `atol` defaults to `rtol / 100` where only `rtol` is given).
    - `solver`: diffrax solver of the forward solve (default: the route's with `method=None`, else
      `Dopri8()`; a `solver` given with `method=None` takes the paper's adjoint); the adjoint and backsolve
      methods integrate backward with the same solver when one is given, else with `Dopri8()`.
      The stiff route, `solver=ffr_jax.Rodas5P()` (a linearly implicit Rosenbrock method, not
      limited by the highest retained frequency), works with every method (tests/test_stiff_route.py).
    - `max_steps`: step budget of each solve. The adjoint method keeps the dense output of its
      forward and backward solves for that many steps (about 1 KB per step each; the reference
      case needs about 8,000 forward and 13,000 backward steps), so the default is 200,000 rather
      than the 1,000,000 of [`objective`][]: raise it for long horizons or low-order solvers.
    - `check`: for a case, check the gradient by its directional derivative along itself against a
      central difference of psi (two more forward solves, [`check_gradient`][]) and raise a
      `ValueError` saying so where they disagree. Every method differentiates a discrete solution;
      autodiff through an explicit solver at its stability limit (many retained modes) can return
      the derivative of the discrete solution with wrong signs (benchmarks/RESULTS.md, "How many
      modes"). Not under `jax.jit`/`jax.vmap` (it needs the values). On by default for `"autodiff"`
      with the default solver where [`choose_route`][] finds the problem stiff (Dopri8 at its
      stability limit), so that such a gradient is right or raises.

    **Returns:** `(psi, grad)`: for a case, `grad` has the structure of `x` (a dict of arrays for a
    dict design, one forward and one backward solve for all bodies); for a problem, a
    pytree like the problem (`grad.scene` the derivatives with respect to every array of the
    scene, `grad.objective` those of the objective's arrays, `grad.y0`, `grad.z0` those of the
    initial state; `None` where a leaf is not a float array). Compiled on the first call and
    reused for equal shapes and settings; works under `jax.vmap` (a batch of designs).

    **Example:**
    ```python
    import ffr_jax as fj
    case = fj.cases.slider_crank()
    psi, grad = fj.value_and_grad(case, case.initial_design(0.5))
    ```
    """
    _checks.float64_on("ffr_jax.value_and_grad")  # before the route, which computes frequencies
    _check_target(target)
    if isinstance(target, Problem) and isinstance(x, (str, AbstractSensitivity)):
        x, method = None, x  # value_and_grad(problem, "autodiff")
    method, solver, rtol, atol, detail = _route(target, method, solver, rtol, atol)
    _check_options("ffr_jax.value_and_grad", rtol, atol, max_steps)
    if isinstance(target, Problem):
        problem, method = _problem_and_method(target, x, method)
        if check:
            raise ValueError("value_and_grad(problem, check=True): the gradient check differences a design; "
                             "build a Case (problem + design map) to check a design gradient.")
        # psi and a gradient like the problem (None where a leaf is no float array): known without tracing
        like = (_scalar_like(problem), jax.tree_util.tree_map(_shape_of, eqx.filter(problem, eqx.is_inexact_array)))
        return _kept(_value_and_grad_problem_fn, (problem, method, rtol, atol, solver, max_steps),
                     f"the gradient of a problem ({detail})",
                     lambda: _value_and_grad_problem(problem, method, rtol, atol, solver, max_steps, detail=detail),
                     out_like=like)
    x = _design(target, x, "value_and_grad")
    directory = None if _checks.is_traced(x) or not cacheable(method) else cache_directory()
    result = None if directory is None else _cached(target, x, method, rtol, atol, solver, max_steps, directory, detail)
    if result is None:  # no cache, a traced design, finite differences or a scene without a stable key
        result = _value_and_grad_design(target, x, method, rtol, atol, solver, max_steps, detail=detail)
    psi, grad = result
    if not check and isinstance(method, Autodiff) and solver is None and not _checks.is_traced(x):
        # Autodiff through the explicit default solver at its stability limit can return the derivative of the
        # discrete solution with wrong signs (20 modes on the 12 x 2 rod: 530x off, benchmarks/RESULTS.md, "Every
        # method at 20 modes"): there the gradient is checked by default, so it is right or raises (issue 32).
        check = choose_route(target).stiff
    if check:
        result = check_gradient(target, x, grad, rtol=rtol, atol=atol, solver=solver)
        if not result.trusted:
            raise ValueError(result.message())
    return psi, grad


@clean_errors
def value_and_grad_scene(target, scene: Scene, method: str | AbstractSensitivity = "adjoint", *,
                         rtol: float = 1e-10, atol: float = 1e-12, solver: diffrax.AbstractSolver | None = None,
                         max_steps: int = 200_000):
    """`(psi, dpsi/dp)` with respect to every array of `scene` (body data, spring constants, crank
    radius, force and law coefficients, ...), for a problem or a case whose problem is run with
    these parameters: a pytree like `scene`, `None` where a leaf is not a float array.
    """
    _check_target(target)
    _check_options("ffr_jax.value_and_grad_scene", rtol, atol, max_steps)
    problem = target if isinstance(target, Problem) else target.problem
    return _value_and_grad_scene(problem, scene, sensitivity_method(method), rtol, atol, solver, max_steps)


def _lower_bound(case: Case) -> float:
    bodies = getattr(case.design_map, "bodies", None)
    if not bodies:
        return 0.0
    return max(float(body.material.x_min) for body in bodies.values())


def check_gradient(case: Case, x, grad, *, step: float = 1e-4, tolerance: float = 1e-3, random_directions: int = 0,
                   seed: int = 0, rtol: float = 1e-10, atol: float = 1e-12, solver=None,
                   max_steps: int = 1_000_000) -> GradientCheck:
    """Check `grad` (of `psi` at design `x`) by its directional derivative along `grad` itself and along
    `random_directions` random directions, against central differences of `psi`.

    Along `d = g / |g|` the gradient under test predicts `g . d = |g|`; the central difference
    measures the true derivative `g_true . d`. The two agree only when `g` is right (or lies on the
    sphere with diameter `g_true`, a coincidence): a gradient with wrong signs or a wrong scale is
    caught by two forward solves. Entries that `x +- h d` would push out of `[x_min, 1]` are left
    out of `d`.

    **Accuracy (the tolerance):** the central difference has truncation error
    `h^2 |psi'''| / 6` and solver noise about `rtol |psi| / h` (the forward solves run at
    `rtol`); with the default `h = 1e-4` and `rtol = 1e-10` both are below `1e-5` of the
    directional derivative on the slider-crank cases (the hard-case table's finite differences
    agree with the adjoint to 1e-10..7e-8 at such steps), so the default `tolerance = 1e-3` leaves
    two orders for cases whose psi is small relative to its gradient, and the wrong gradients this
    guard exists for are off by factors, not by 1e-3.

    **Arguments:**
    - `case`, `x`: the case and its design (flat array or dict by body); `grad`: the gradient
      under test, shaped like `x`.
    - `step`: `h`, in design units along the unit direction; `tolerance`: see above.
    - `random_directions`: extra random unit directions (two forward solves each); `seed`.
    - `rtol`, `atol`, `solver`, `max_steps`: the forward solves (as in [`objective`][]).

    **Returns:** a `GradientCheck`; `raise ValueError(check.message())` where `not check.trusted`
    is what `value_and_grad(..., check=True)` does.
    """
    return compare_with_differences(
        lambda y: objective(case, y, rtol=rtol, atol=atol, solver=solver, max_steps=max_steps), x, grad,
        lower=_lower_bound(case), step=step, tolerance=tolerance, random_directions=random_directions, seed=seed)
