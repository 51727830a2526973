"""The bad inputs of issue 17, as data: each one call of the public API or one `ffr-jax` command line,
the error it must raise and where it is caught.

Shared by `tests/test_bad_input_fuzz.py` (which asserts every row) and `benchmarks/bench_bad_input.py`
(which times every row and writes the "Bad input" table of benchmarks/RESULTS.md), so that both
check exactly the same list. Adding a case is one line in `API` or `CLI`.

Every call runs on one small slider-crank (`Ctx.case`: a 4 x 2 rod, 2 modes, 0.1 s with a 0.05 s
run-up, so that the crank passes phi = pi/2 at full speed, where this rod with a crank of 0.99 l or
longer is pulled through its dead point). Most
inputs are refused before anything is traced; the few that need a compiled program (a dead point
reached along the motion) share the case's structure, so one compiled forward solve serves them, and
one compiled finite-difference program (`Ctx.gradient`) serves the batched rows and the tests of
finite differences at the bounds; a
bad design under a user's `jax.jit` runs in the (cheap) jitted modal solve of the case.
"""

import contextlib
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax as fj
from ffr_jax._app._checkpoint import Checkpoint, save_checkpoint
from ffr_jax._design.geometry import rod_joint_nodes
from ffr_jax._design.mesh import StructuredGrid

NAN, INF = float("nan"), float("inf")
# The small case: nx, ny, n_modes, t1 and the run-up time.
SMALL = dict(nx=4, ny=2, n_modes=2, t1=0.1, t_ramp=0.05)


def slider_crank(**changes):
    args = {**SMALL, **changes}
    return fj.cases.slider_crank(args.pop("nx"), args.pop("ny"), args.pop("n_modes"), args.pop("t1"), **args)


def variant(base, other):
    """The array values of `other` in the static structure of `base` (one compiled program for both)."""
    arrays = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(eqx.filter(base, eqx.is_array)),
                                          jax.tree_util.tree_leaves(eqx.filter(other, eqx.is_array)))
    return eqx.combine(arrays, eqx.filter(base, eqx.is_array, inverse=True))


@dataclass
class Ctx:
    """What the calls share: the small case, its uniform design, a user's jitted objective, a scratch directory."""

    tmp: Path
    case: Any = None
    x: Any = None
    jitted: Any = None

    def __post_init__(self):
        self.case = slider_crank()
        self.x = self.case.initial_design(0.5)
        # A user's own jax.jit around a function of the package. The design check that fails in it is the
        # first step of every design program (objective, gradients, modes), so the cheapest one serves:
        # the modes (a jitted objective costs a second compilation of the forward solve).
        case = self.case
        self.jitted = jax.jit(lambda x: case.frequencies(x))

    def fd(self, x, **options):
        return fj.value_and_grad(self.case, x, fj.FiniteDifferences(**options))

    # The finite differences of three entries: one compiled program (seven forward solves in one batch)
    # that serves the dead-point rows (its first solve stops there) and the tests of finite
    # differences at the bounds, so that the module compiles the forward solve only once.
    FD = fj.FiniteDifferences(step=1e-4, entries=(0, 1, 2), batch_size=7)

    def gradient(self, case, x):
        return fj.value_and_grad(case, x, self.FD)

    def checkpoint(self, name: str, x=None, leaves=(), history=None) -> Path:
        """A run directory `tmp/name` holding a checkpoint of the small CLI run with the given values."""
        directory = self.tmp / name
        directory.mkdir(exist_ok=True)
        n_design = 2 * (4 - 2)  # the CLI runs below use --nx 4 --ny 2 (as the small case)
        x = np.full(n_design, 0.5) if x is None else np.asarray(x, dtype=float)
        history = fj.History(np.ones(1), np.full(1, 0.5), np.full(1, 0.01)) if history is None else history
        config = {"volume": 0.5, "optimizer": "adam", "lr": 0.02, "move": 0.05, "filter_radius": 1.5,
                  "method": "adjoint", "nx": 4, "ny": 2, "modes": 2, "t1": 0.05, "rtol": 1e-6, "atol": 1e-10,
                  "beta": 0.0, "beta_max": 32.0, "beta_every": 20, "eta": 0.5, "case": "slider-crank"}
        save_checkpoint(directory / "checkpoint.npz", Checkpoint(1, x, tuple(leaves), history, config))
        return directory

    def truncated_checkpoint(self, name: str) -> Path:
        directory = self.checkpoint(name)
        path = directory / "checkpoint.npz"
        path.write_bytes(path.read_bytes()[:200])
        return directory


@contextlib.contextmanager
def user_view():
    """What a user sees: the calls run without the test suite's runtime type-checking hook (pytest's
    `--jaxtyping-packages`), which would otherwise refuse e.g. `rtol=1` (an int for a `float`) before
    the package's own check reads it."""
    import jaxtyping

    before = jaxtyping.config.jaxtyping_disable
    jaxtyping.config.update("jaxtyping_disable", True)
    try:
        yield
    finally:
        jaxtyping.config.update("jaxtyping_disable", before)


@dataclass(frozen=True)
class Bad:
    """One bad input through the API: `call(ctx)` must raise `error` with a message matching `match`."""

    name: str
    call: Callable[[Ctx], Any]
    error: type | tuple
    match: str
    where: str


@dataclass(frozen=True)
class BadCli:
    """One bad command line: `ffr-jax ARGV` (`{tmp}` is the scratch directory, `{setup}` the directory
    that `setup(ctx)` returns) must exit with status 2 and one line `ffr-jax: error: ...` matching `match`."""

    name: str
    argv: str
    match: str
    where: str
    setup: Callable[[Ctx], Path] | None = field(default=None)


def with_design(ctx: Ctx, **entries):
    x = ctx.x
    for k, v in entries.items():
        x = x.at[int(k[1:])].set(v)
    return x


V = ValueError
DE = fj.DesignError
SE = fj.SimulationError
CE = fj.CheckpointError
RTOL = r"rtol of .* must (be positive|lie in \[1e-14, 0.01\))"

API = [
    # --- silent wrong results before issue 17 ------------------------------------------------------
    Bad("t1 = nan", lambda c: slider_crank(t1=NAN), V, r"slider_crank\(t1=...\) must be finite", "slider_crank()"),
    Bad("t1 = inf", lambda c: slider_crank(t1=INF), V, r"t1=...\) must be finite", "slider_crank()"),
    Bad("t1 = 0", lambda c: slider_crank(t1=0.0), V, r"t1=...\) must be positive", "slider_crank()"),
    Bad("Problem t1 = nan", lambda c: fj.Problem(c.case.problem.scene, NAN, positions=np.zeros(3),
                                                 objective=c.case.problem.objective), V, "t1 must be finite", "Problem()"),
    Bad("objective rtol = 1", lambda c: fj.objective(c.case, c.x, rtol=1), V, RTOL, "objective() entry"),
    Bad("objective rtol = -1", lambda c: fj.objective(c.case, c.x, rtol=-1), V, RTOL, "objective() entry"),
    Bad("objective rtol = 0", lambda c: fj.objective(c.case, c.x, rtol=0.0), V, RTOL, "objective() entry"),
    Bad("objective rtol = nan", lambda c: fj.objective(c.case, c.x, rtol=NAN), V, "rtol .* must be finite",
        "objective() entry"),
    Bad("objective atol = -1e-12", lambda c: fj.objective(c.case, c.x, atol=-1e-12), V, "atol .* must be positive",
        "objective() entry"),
    Bad("value_and_grad rtol = -1", lambda c: fj.value_and_grad(c.case, c.x, rtol=-1), V, RTOL,
        "value_and_grad() entry"),
    Bad("Backsolve(rtol=-1)", lambda c: fj.Backsolve(rtol=-1), V, RTOL, "Backsolve()"),
    Bad("Backsolve(atol=-1)", lambda c: fj.Backsolve(atol=-1), V, "atol .* must be positive", "Backsolve()"),
    Bad("Adjoint(rtol=0)", lambda c: fj.Adjoint(rtol=0.0), V, RTOL, "Adjoint()"),
    Bad("Adjoint(atol=-1)", lambda c: fj.Adjoint(atol=-1.0), V, "atol .* must be positive", "Adjoint()"),
    Bad("FiniteDifferences(step=0)", lambda c: fj.FiniteDifferences(step=0.0), V, r"step=...\) must be positive",
        "FiniteDifferences()"),
    Bad("FiniteDifferences(step=-1e-5)", lambda c: fj.FiniteDifferences(step=-1e-5), V, "must be positive",
        "FiniteDifferences()"),
    Bad("FiniteDifferences(step=nan)", lambda c: fj.FiniteDifferences(step=NAN), V, "must be finite",
        "FiniteDifferences()"),
    Bad("FiniteDifferences(step=0.6)", lambda c: c.fd(c.x, step=0.6), V, r"below \(1 - x_min\) / 2",
        "value_and_grad() trace"),
    Bad("FiniteDifferences(entries=(99,))", lambda c: c.fd(c.x, entries=(99,)), V, "holds index 99, but the design "
        "has 4 variables", "value_and_grad() trace"),
    Bad("FiniteDifferences(entries=(-1,))", lambda c: fj.FiniteDifferences(entries=(-1,)), V, "integer >= 0",
        "FiniteDifferences()"),
    Bad("FiniteDifferences(entries=())", lambda c: fj.FiniteDifferences(entries=()), V, "selects no design variable",
        "FiniteDifferences()"),
    Bad("FiniteDifferences(batch_size=0)", lambda c: fj.FiniteDifferences(batch_size=0), V,
        r"batch_size=...\) must be an integer >= 1", "FiniteDifferences()"),
    Bad("DensityFilter(radius=inf)", lambda c: fj.DensityFilter(c.case.design, INF), V, "finite non-negative",
        "DensityFilter()"),
    Bad("DensityFilter(radius=nan)", lambda c: fj.DensityFilter(c.case.design, NAN), V, "finite non-negative",
        "DensityFilter()"),
    Bad("DensityFilter(radius=-1)", lambda c: fj.DensityFilter(c.case.design, -1.0), V, "finite non-negative",
        "DensityFilter()"),
    Bad("SIMP(x_min=0)", lambda c: fj.SIMP(x_min=0.0), V, r"x_min=...\) must lie in \(0, 1\)", "SIMP()"),
    Bad("SIMP(x_min=-0.1)", lambda c: fj.SIMP(x_min=-0.1), V, r"x_min=...\) must lie in \(0, 1\)", "SIMP()"),
    Bad("SIMP(stiffness_penalty=-3)", lambda c: fj.SIMP(stiffness_penalty=-3.0), V, "stiffness_penalty=...\\) must "
        "be positive", "SIMP()"),
    Bad("SIMP(mass_penalty=-6)", lambda c: fj.SIMP(mass_penalty=-6.0), V, "mass_penalty", "SIMP()"),
    Bad("SIMP(mass_factor=-1e5)", lambda c: fj.SIMP(mass_factor=-1e5), V, "mass_factor", "SIMP()"),
    Bad("SIMP(x_switch=1.5)", lambda c: fj.SIMP(x_switch=1.5), V, r"x_switch=...\) must lie in \(0, 1\]", "SIMP()"),
    Bad("SIMP(density=-8750)", lambda c: fj.SIMP(density=-8750.0), V, "density=...\\) must be positive", "SIMP()"),
    Bad("SIMP(youngs_modulus=nan)", lambda c: fj.SIMP(youngs_modulus=NAN), V, "must be finite", "SIMP()"),
    Bad("complex design", lambda c: fj.objective(c.case, c.x.astype(complex)), DE, "is complex", "design check"),
    Bad("float32 design at x_min", lambda c: fj.objective(c.case, jnp.full(4, 0.01, jnp.float32)), DE,
        "within float32 rounding of x_min", "design check"),
    Bad("string design", lambda c: fj.objective(c.case, np.array(["a"] * 4)), DE, "real numbers", "design check"),
    # --- right error, wrong message before issue 17 ------------------------------------------------
    Bad("density 1.5 under jax.vmap", lambda c: jax.vmap(lambda x: fj.objective(c.case, x))(
        jnp.stack([c.x, with_design(c, x3=1.5)])), DE, r"must lie in \[x_min, 1\]", "design check (vmap)"),
    Bad("NaN density under jax.vmap", lambda c: jax.vmap(lambda x: fj.objective(c.case, x))(
        jnp.stack([c.x, with_design(c, x3=NAN)])), DE, "contains NaN or inf", "design check (vmap)"),
    Bad("inf density under jax.vmap", lambda c: jax.vmap(lambda x: fj.value_and_grad(c.case, x))(
        jnp.stack([with_design(c, x0=INF), c.x])), DE, "contains NaN or inf", "design check (vmap)"),
    Bad("density 1.5 under jax.jit + clean_errors", lambda c: fj.clean_errors(c.jitted)(with_design(c, x3=1.5)), DE,
        r"^Design densities must lie in \[x_min, 1\]", "compiled check (user's jit)"),
    Bad("NaN density under jax.jit + clean_errors", lambda c: fj.clean_errors(c.jitted)(with_design(c, x3=NAN)), DE,
        "^Design vector contains NaN or inf", "compiled check (user's jit)"),
    Bad("max_steps = 0", lambda c: fj.objective(c.case, c.x, max_steps=0), V, "max_steps .* integer >= 1",
        "objective() entry"),
    Bad("max_steps = -1", lambda c: fj.objective(c.case, c.x, max_steps=-1), V, "max_steps .* integer >= 1",
        "objective() entry"),
    Bad("max_steps = 10.5", lambda c: fj.objective(c.case, c.x, max_steps=10.5), V, "max_steps .* integer >= 1",
        "objective() entry"),
    Bad("Adjoint(max_steps=0)", lambda c: fj.Adjoint(max_steps=0), V, r"Adjoint\(max_steps=...\) must be an integer >= 1",
        "Adjoint()"),
    Bad("Direct(chunk=0)", lambda c: fj.Direct(chunk=0), V, r"Direct\(chunk=...\) must be an integer >= 1", "Direct()"),
    Bad("Autodiff(checkpoints=2.5)", lambda c: fj.Autodiff(checkpoints=2.5), V, "checkpoints=...\\) must be an integer",
        "Autodiff()"),
    Bad("n_modes = 3.0", lambda c: slider_crank(n_modes=3.0), V, r"n_modes=...\) must be an integer", "slider_crank()"),
    Bad("dead point, eccentricity 0.999 l", lambda c: fj.objective(variant(c.case, slider_crank(eccentricity=0.999)),
                                                                   c.x), SE, "^Dead point", "compiled (Newton check)"),
    Bad("dead point, eccentricity 0.99999 l", lambda c: fj.objective(
        variant(c.case, slider_crank(eccentricity=0.99999)), c.x), SE, "^Dead point", "compiled (Newton check)"),
    # Known weaker: in the batched solves of finite differences the first error raised can be Newton's
    # (a lane's trial step beyond the dead point, where the linkage cannot assemble) rather than the
    # dead-point check; still a SimulationError that names the geometry, never a number.
    Bad("dead point, 0.99999 l, finite differences (batched)", lambda c: c.gradient(
        variant(c.case, slider_crank(eccentricity=0.99999)), c.x), SE, "^Dead point|^Newton's method .* did not "
        "converge", "compiled (Newton check, batched)"),
    Bad("checkpoint with NaN design", lambda c: fj.load_checkpoint(c.checkpoint("nan_x", x=[0.5, NAN, 0.5, 0.5])
                                                                   / "checkpoint.npz"),
        CE, r"checkpoint.npz holds a design with NaN", "load_checkpoint()"),
    Bad("checkpoint with density 1.5", lambda c: fj.load_checkpoint(c.checkpoint("big_x", x=[0.5, 1.5, 0.5, 0.5])
                                                                    / "checkpoint.npz"),
        CE, "holds a design with densities outside", "load_checkpoint()"),
    Bad("checkpoint with NaN optimizer state", lambda c: fj.load_checkpoint(
        c.checkpoint("nan_state", leaves=(np.array([0.0, NAN]),)) / "checkpoint.npz"),
        CE, "NaN or inf in optimizer state", "load_checkpoint()"),
    # --- handled before issue 17 (kept so that they stay handled) ----------------------------------
    Bad("design of the wrong length", lambda c: fj.objective(c.case, c.x[:-1]), DE, r"has shape \(3,\), expected",
        "design check"),
    Bad("design density 0.005 < x_min", lambda c: fj.objective(c.case, with_design(c, x0=0.005)), DE,
        r"must lie in \[x_min, 1\] = \[0.01, 1\]", "design check"),
    Bad("design density inf", lambda c: fj.value_and_grad(c.case, with_design(c, x0=INF)), DE, "NaN or inf",
        "design check"),
    Bad("nx = 3", lambda c: slider_crank(nx=3), V, "nx", "slider_crank()"),
    Bad("ny = 3 (odd)", lambda c: slider_crank(ny=3), V, "ny must be even", "slider_crank()"),
    Bad("n_modes = 0", lambda c: slider_crank(n_modes=0), V, "n_modes", "slider_crank()"),
    Bad("n_modes = 50 (too many)", lambda c: slider_crank(n_modes=50).frequencies(c.x), V, "n_modes=50",
        "modal solver (trace)"),
    Bad("eccentricity = l", lambda c: slider_crank(eccentricity=1.0), V, r"eccentricity must lie in \(0, l\)",
        "slider_crank()"),
    Bad("eccentricity = nan", lambda c: slider_crank(eccentricity=NAN), V, "eccentricity.* must be finite",
        "slider_crank()"),
    Bad("initial_design(1.5)", lambda c: c.case.initial_design(1.5), V, r"outside \[x_min, 1\]", "initial_design()"),
    Bad("VolumeConstraint(1.5)", lambda c: fj.VolumeConstraint(1.5), V, "volume fraction must lie", "VolumeConstraint()"),
    Bad("HeavisideProjection(eta=1)", lambda c: fj.HeavisideProjection(1.0), V, "eta must lie in", "HeavisideProjection()"),
    Bad("unknown method", lambda c: fj.value_and_grad(c.case, c.x, "newton"), V, "newton", "value_and_grad() entry"),
    Bad("truncated checkpoint", lambda c: fj.load_checkpoint(c.truncated_checkpoint("cut") / "checkpoint.npz"), CE,
        "corrupt or incomplete", "load_checkpoint()"),
    Bad("missing checkpoint", lambda c: fj.load_checkpoint(c.tmp / "none" / "checkpoint.npz"), CE, "checkpoint",
        "load_checkpoint()"),
]

# --- issue 32: bad input that still got through ---------------------------------------------------
# Each row names the outcome the issue reported (before) in its comment; the row is the outcome now.


def _crank() -> fj.Body:
    return fj.Body("crank", fj.rigid_body_data(1.0, (0.05, 0.0), 0.01, [(0.0, 0.0), (0.1, 0.0)]))


def _two_bodies(c: Ctx, constraints=(), forces=()):
    return fj.Scene((c.case.problem.scene.bodies[0], _crank()), tuple(constraints), tuple(forces))


_NOT_A_MARKER = r"is not a marker of body \d .*valid indices are 0 to 1"
_NOT_A_BODY = r"is not a body of the scene: valid indices are 0 to"
def _garbage_file(c) -> str:
    path = c.tmp / "garbage.msh"
    path.write_bytes(b"garbage\x00\x01 not a mesh")
    return str(path)


API_32 = [
    # Silently wrong before (JAX's gather clamps a marker index to the last marker; a negative body index
    # counts from the end): refused where the element meets the scene, naming the element, index and range.
    Bad("Revolute(marker_j=7) on a body with 2 markers", lambda c: _two_bodies(c, [fj.Revolute(0, 0, 1, 7)]), V,
        r"constraints\[0\] \(Revolute\)\.marker_j = 7 " + _NOT_A_MARKER, "Scene()"),
    Bad("Revolute to body 2 of 2", lambda c: _two_bodies(c, [fj.Revolute(0, 0, 2, 0)]), V,
        r"Revolute\)\.body_j = 2 " + _NOT_A_BODY + " 1", "Scene()"),
    Bad("GroundRevolute(body=-1)", lambda c: _two_bodies(c, [fj.GroundRevolute(-1, 0)]), V,
        r"GroundRevolute\)\.body = -1 " + _NOT_A_BODY + " 1.*negative index does not count from the end",
        "Scene()"),
    Bad("SpringDamper on marker 9", lambda c: _two_bodies(c, forces=[fj.SpringDamper(0, 9, stiffness=1.0)]), V,
        r"forces\[0\] \(SpringDamper\)\.marker_i = 9 " + _NOT_A_MARKER, "Scene()"),
    Bad("MarkerTracking(body=0, marker=9)", lambda c: c.case.with_objective(fj.MarkerTracking(0, 9, (0.0, 0.0))), V,
        r"MarkerTracking\.marker = 9 " + _NOT_A_MARKER, "Problem() (objective)"),
    Bad("MarkerTracking(body=1) on a one-body scene", lambda c: c.case.with_objective(
        fj.MarkerTracking(1, 0, (0.0, 0.0))), V, r"MarkerTracking\.body = 1 " + _NOT_A_BODY + " 0",
        "Problem() (objective)"),
    Bad("Compliance(body=-1) inside a weighted sum", lambda c: c.case.with_objective(
        fj.KineticEnergy() + 2.0 * fj.Compliance(-1)), V, r"Compliance\.body = -1 " + _NOT_A_BODY, "Problem() (objective)"),
]


def _rod_with_detached_piece() -> fj.DesignedBody:
    """The small rod (4 x 2 Q4, 2 hinged-hinged modes) and a 0.1 m square element that shares no node with
    it: a rigid-body mode of the piece is the lowest eigenpair (omega^2 = -1e-6 of a scale 3.6e9)."""
    grid = StructuredGrid(4, 2, 1.0, 0.06)
    nodes, elements = np.asarray(grid.nodes), np.asarray(grid.elements)
    n = len(nodes)
    piece = np.array([[0.4, 0.2], [0.5, 0.2], [0.5, 0.3], [0.4, 0.3]])
    mesh = fj.QuadMesh(np.vstack([nodes, piece]), np.vstack([elements, [[n, n + 1, n + 2, n + 3]]]))
    a, b = rod_joint_nodes(4, 2)
    return fj.DesignedBody(fj.FEModel(mesh, fj.Q4(), 0.01, 0.3), fj.DesignDomain(mesh), fj.SIMP(),
                           fj.ModalReduction(2, fj.HingedHinged(a, b), solver=fj.DenseModes()), (a, b))


def _rod_with(extra_nodes=(), extra_elements=(), height=0.06, element=None, solver=None) -> fj.DesignedBody:
    """The small rod (4 x 2 elements, 2 hinged-hinged modes, markers A and B) with extra nodes and elements
    (indices of the extra nodes counted from the rod's node count)."""
    grid = StructuredGrid(4, 2, 1.0, height)
    nodes, elements = np.asarray(grid.nodes), np.asarray(grid.elements)
    n = len(nodes)
    extra = [[node if node >= 0 else n - 1 - node for node in e] for e in extra_elements]  # -1: the first extra node
    mesh = fj.QuadMesh(np.vstack([nodes, *([np.asarray(extra_nodes)] if len(extra_nodes) else [])]),
                       np.vstack([elements, *([np.asarray(extra)] if extra else [])]))
    a, b = rod_joint_nodes(4, 2)
    return fj.DesignedBody(fj.FEModel(mesh, element or fj.Q4(), 0.01, 0.3), fj.DesignDomain(mesh), fj.SIMP(),
                           fj.ModalReduction(2, fj.HingedHinged(a, b), solver=solver or fj.DenseModes()), (a, b))


def _rod_with_flap() -> fj.DesignedBody:
    """A 0.1 m square element hinged at the rod's top right corner node (1, 0.03) alone: a mechanism."""
    corner = 3 * 5 - 1  # StructuredGrid(4, 2): node (i, j) = i * 3 + j, the corner (4, 2)
    return _rod_with([[1.1, 0.03], [1.1, 0.13], [1.0, 0.13]], [[corner, -1, -2, -3]])


def _detached_case(c: Ctx) -> fj.Case:
    """The small case's problem with the detached-piece rod as its designed body (its scene's template data
    come from the healthy rod: the data have the same shapes, so the case is accepted and the design map
    must refuse the body)."""
    return fj.Case(c.case.problem, fj.DesignMap({"rod": _rod_with_detached_piece()}))


def _at_half(case, method: str | None = None):
    """`(case, x)` at the uniform design 0.5, or `case.method(x)`."""
    x = case.initial_design(0.5)
    return (case, x) if method is None else getattr(case, method)(x)


def _negative_stiffness(c: Ctx):
    scene = c.case.problem.scene
    return eqx.tree_at(lambda s: s.bodies[0].data.modal_stiffness, scene, -scene.bodies[0].data.modal_stiffness)


_MECHANISM = "found a rigid-body or mechanism mode"
API_32 += [
    # Silently wrong before (psi 5.3e-12 instead of 9.3e-3; case.frequencies() alone refused): the modal check
    # guards the modes as well as the eigenvalues, so every path that builds body data refuses the body.
    Bad("detached piece: uniform_body_data()", lambda c: _rod_with_detached_piece().uniform_body_data(), DE,
        _MECHANISM, "modal check (compiled)"),
    Bad("detached piece, LanczosModes: uniform_body_data()", lambda c: _rod_with(
        [[0.4, 0.2], [0.5, 0.2], [0.5, 0.3], [0.4, 0.3]], [[-1, -2, -3, -4]], solver=fj.LanczosModes()
    ).uniform_body_data(), DE, _MECHANISM, "modal check (Lanczos, compiled)"),
    Bad("flap hinged at one node: uniform_body_data()", lambda c: _rod_with_flap().uniform_body_data(), DE,
        _MECHANISM, "modal check (compiled)"),
    # Q4 locks by a factor 3.4e5 at this aspect ratio, QM6 gives a negative omega^2: both are round-off (the lowest
    # eigenvalue at 5e-15 and -8e-16 of the stiffness scale, see ffr_jax._design.modal.base.check_modes).
    Bad("rod of 1e6-aspect elements (Q4): uniform_body_data()", lambda c: _rod_with(height=1e-6).uniform_body_data(),
        DE, _MECHANISM, "modal check (compiled)"),
    Bad("rod of 1e6-aspect elements (QM6): uniform_body_data()", lambda c: _rod_with(
        height=1e-6, element=fj.QM6()).uniform_body_data(), DE, _MECHANISM, "modal check (compiled)"),
    Bad("detached piece: case.body_data(x)", lambda c: _at_half(_detached_case(c), "body_data"), DE, _MECHANISM,
        "modal check"),
    Bad("detached piece: fj.objective(case, x)", lambda c: fj.objective(*_at_half(_detached_case(c))), DE, _MECHANISM,
        "modal check (objective program)"),
    # psi = -4.8e152 before: data edited with eqx.tree_at skip BodyData's own checks.
    Bad("negative modal stiffness (eqx.tree_at) -> Problem.with_scene", lambda c: c.case.problem.with_scene(
        _negative_stiffness(c)), V, r"Body 0 \('rod'\) of the scene: BodyData.modal_stiffness must be positive "
        "semi-definite", "Problem.with_scene()"),
    Bad("negative modal stiffness (eqx.tree_at) -> Problem()", lambda c: fj.Problem(
        _negative_stiffness(c), 0.1, positions=c.case.problem.y_r0, objective=fj.Compliance(0)), V,
        "modal_stiffness must be positive semi-definite", "Problem()"),
    Bad("negative modal stiffness (eqx.tree_at on a built problem) -> fj.objective(problem)", lambda c: fj.objective(
        eqx.tree_at(lambda p: p.scene, c.case.problem, _negative_stiffness(c))), V,
        r"Body 0 \('rod'\) of the scene: BodyData.modal_stiffness must be positive semi-definite", "objective() entry"),
    # SystemExit(1) from meshio before.
    Bad("fj.read_mesh of a garbage file", lambda c: fj.read_mesh(_garbage_file(c)), V,
        "read_mesh: meshio could not read .* give a mesh file meshio reads", "read_mesh()"),
    # Newton's "cannot assemble ... check the scene geometry" before.
    Bad("NaN output times", lambda c: fj.simulate(c.case, c.x, ts=jnp.array([0.0, NAN])), V,
        "output times ts must be finite", "simulate() entry"),
]
_BETA = "beta must be a finite positive number"
API_32 += [
    # NaN psi and gradient before (beta = inf passed the check `beta <= 0`); fj.optimize(beta=inf) never moved.
    Bad("HeavisideProjection beta = inf", lambda c: fj.HeavisideProjection(0.5)(c.x, INF), V, _BETA,
        "HeavisideProjection.__call__"),
    Bad("HeavisideProjection beta = nan", lambda c: fj.HeavisideProjection(0.5)(c.x, NAN), V, _BETA,
        "HeavisideProjection.__call__"),
    Bad("HeavisideProjection beta = inf under jax.jit + clean_errors", lambda c: fj.clean_errors(jax.jit(
        fj.HeavisideProjection(0.5)))(c.x, INF), DE, "^The projection sharpness " + _BETA, "compiled check"),
    Bad("beta_continuation(1, inf)", lambda c: fj.beta_continuation(1.0, INF, 10), V, "finite start, stop",
        "beta_continuation()"),
    Bad("fj.optimize(beta=inf)", lambda c: fj.optimize(lambda x: (jnp.sum(x), jnp.ones_like(x)), c.x, fj.MMA(),
                                                       iterations=1, beta=INF), V, r"optimize\(beta=...\).*" + _BETA,
        "optimize() entry"),
]
API_32 += [
    # A gradient 3.6x off without a word before: steps below 100 rtol (the noise floor) are refused at trace time.
    Bad("FiniteDifferences(step=1e-12) at rtol 1e-10", lambda c: c.fd(c.x, step=1e-12), V,
        r"step=1e-12\) is below the noise floor .* at least 100 rtol = 1e-08", "value_and_grad() trace"),
    Bad("FiniteDifferences(step=1e-5) at rtol 1e-6", lambda c: fj.value_and_grad(
        c.case, c.x, fj.FiniteDifferences(step=1e-5), rtol=1e-6), V, "noise floor .* at least 100 rtol = 0.0001",
        "value_and_grad() trace"),
]
API_32 += [
    # Misleading before: a NaN parameter surfaced as Newton's "cannot assemble ... check the scene geometry" (or as
    # "scale must be positive"); now refused at construction with the field named.
    Bad("SpringDamper(stiffness=nan)", lambda c: fj.SpringDamper(0, 0, stiffness=NAN), V,
        "SpringDamper stiffness must be finite", "SpringDamper()"),
    Bad("Gravity((0, nan))", lambda c: fj.Gravity((0.0, NAN)), V, "Gravity acceleration must be finite", "Gravity()"),
    Bad("ConstantSpeedLaw(nan)", lambda c: fj.ConstantSpeedLaw(NAN), V, "ConstantSpeedLaw speed must be finite",
        "ConstantSpeedLaw()"),
    Bad("RampLaw(angle_at_ramp=nan)", lambda c: fj.RampLaw(1.0, NAN), V, "RampLaw angle_at_ramp must be finite",
        "RampLaw()"),
    Bad("PointOnLine(direction=(0, 0))", lambda c: fj.PointOnLine(0, 1, direction=(0.0, 0.0)), V,
        "direction must be a non-zero", "PointOnLine()"),
    Bad("CrankPin(radius=nan)", lambda c: fj.CrankPin(0, 0, NAN, fj.ConstantSpeedLaw(1.0)), V,
        "CrankPin radius must be finite", "CrankPin()"),
    Bad("FunctionConstraint with a NaN bound", lambda c: fj.FunctionConstraint(lambda x: (jnp.sum(x), x), NAN), V,
        "FunctionConstraint 'function': bound must be finite", "FunctionConstraint()"),
    # A broadcasting TypeError inside MMA's update after 11 s before; now before anything compiles (the
    # objective's gradient shape from jax.eval_shape).
    Bad("MMA with x0 of the wrong length", lambda c: fj.optimize(fj.make_objective(c.case), jnp.full(3, 0.5), fj.MMA(),
                                                               fj.VolumeConstraint(0.5), iterations=1), V,
        r"x0 has 3 densities, but the objective's case has 4", "optimize() entry"),
    Bad("MMA with x0 of the wrong length, a user's objective", lambda c: fj.optimize(
        lambda x: (jnp.sum(x), jnp.ones(4)), jnp.full(3, 0.5), fj.MMA(), iterations=1), V,
        r"gradient has shape \(4,\), but the design x has shape \(3,\)", "optimize() step trace"),
]
def _without_x64(call):
    """`call()` with JAX's float64 mode turned off, as by a user after `import ffr_jax` (turned on again after)."""
    jax.config.update("jax_enable_x64", False)
    try:
        return call()
    finally:
        jax.config.update("jax_enable_x64", True)


_X64 = r"ffr_jax computes in float64, but JAX's float64 mode \(jax_enable_x64\) is off: .* jax.config.update\('jax_enable_x64', True\)"
API_32 += [
    # "lax.add requires arguments to have the same dtypes" from deep inside the trace before; now the door says it.
    Bad("x64 turned off after import: fj.value_and_grad", lambda c: _without_x64(lambda: fj.value_and_grad(c.case, c.x)),
        V, "^ffr_jax.value_and_grad: " + _X64, "value_and_grad() entry"),
    Bad("x64 turned off after import: fj.objective", lambda c: _without_x64(lambda: fj.objective(c.case, c.x)), V,
        "^ffr_jax.objective: " + _X64, "objective() entry"),
    Bad("x64 turned off after import: fj.simulate", lambda c: _without_x64(lambda: fj.simulate(c.case, c.x)), V,
        "^ffr_jax.simulate: " + _X64, "simulate() entry"),
]
def _nan_integrand(c: Ctx) -> fj.Problem:
    """The small case's scene with a user's integrand that turns NaN at t = 0.06 s (of 0.1 s)."""
    problem = c.case.problem
    integrand = fj.FunctionIntegrand(lambda t, y_r, z_r, scene: jnp.where(t > 0.06, jnp.nan, 1.0) * jnp.sum(z_r**2))
    return fj.Problem(problem.scene, problem.t1, positions=problem.initial_state()[0], objective=integrand)


def non_grashof_four_bar(t1: float, dt0: float | None = None) -> fj.Case:
    """A four-bar that is no Grashof linkage (crank 0.4, coupler 1, rocker 0.5, ground 1.2: s + l = 1.6 > p + q =
    1.5), as a user's own scene: `fj.cases.four_bar` refuses these lengths, so its code builds the scene with the
    check left out. Its crank can turn from 0 to its limit angle 2.31 rad (|O2 - P| = coupler + rocker), which
    the run-up law phi = 2 pi t^2 reaches at t = 0.607 s."""
    from unittest import mock

    with mock.patch("ffr_jax.cases._four_bar.check_grashof"):
        case = fj.cases.four_bar(4, 2, 2, t1, crank=0.4, rocker=0.5, ground=1.2)
    if dt0 is None:
        return case
    p = case.problem
    problem = fj.Problem(p.scene, t1, positions=p.initial_state()[0], objective=p.objective,
                         partition=p.model.partition, dependent_guess=p.model.dependent_guess, dt0=dt0)
    return fj.Case(problem, case.design_map)


# Rows that compile a program of their own (a new integrand, another scene): slow-marked in test_bad_input_fuzz.
SLOW_32 = [
    # "The maximum number of solver steps was reached ... increase max_steps" after 197 s before (a small budget
    # here: the stall is the same at any budget).
    Bad("integrand turning NaN midway: fj.objective", lambda c: fj.objective(_nan_integrand(c), max_steps=4000), SE,
        "^The objective's integrand F turned NaN or inf along the motion", "compiled (failed solve)"),
    Bad("integrand turning NaN midway: fj.value_and_grad autodiff", lambda c: fj.value_and_grad(
        _nan_integrand(c), "autodiff", max_steps=4000), SE, "^The objective's integrand F turned NaN", "compiled (failed solve)"),
    # A long horizon on the cached gradient (nan-mode programs, which fj.value_and_grad and the CLI run): before, the
    # step count of the failed solve became the largest integer there and the adjoint's quadrature looped without
    # end (the CLI gave no result in 1,500 s; from Python, over 20 minutes at t1 = 300). A small budget: the same
    # failure at any budget.
    Bad("t1 = 1000 through the cached gradient: fj.value_and_grad(max_steps=2000)", lambda c: fj.value_and_grad(
        slider_crank(t1=1000.0), slider_crank(t1=1000.0).initial_design(0.5), "adjoint", max_steps=2000), SE,
        "^The maximum number of solver steps was reached", "compiled (step budget)"),
    # The limit angle reached (t1 = 0.8 s): a toggle position, where the coupler and rocker are collinear.
    Bad("non-Grashof four-bar driven past its limit angle", lambda c: fj.objective(*_at_half(non_grashof_four_bar(0.8))),
        SE, "^Dead point", "compiled (dead-point check)"),
]
API += API_32

# Every command line has the small mesh; the bad option is what fails, before anything compiles.
G = "gradient slider-crank --nx 4 --ny 2 --modes 2 --t1 0.05"
O = "optimize slider-crank --nx 4 --ny 2 --modes 2 --t1 0.05 --iters 1"
CLI = [
    BadCli("--t1 nan", "gradient slider-crank --t1 nan", "--t1 must be finite", "CLI options"),
    BadCli("--rtol -1", f"{G} --rtol -1", "rtol of the forward solve .* must be positive", "CLI options"),
    BadCli("--rtol 1", f"{G} --rtol 1", r"must lie in \[1e-14, 0.01\)", "CLI options"),
    BadCli("--atol -1", f"{G} --atol -1", "atol of the forward solve .* must be positive", "CLI options"),
    BadCli("--backward-rtol nan", f"{G} --backward-rtol nan", "must be finite", "CLI options"),
    BadCli("--fd-step 0", f"{G} --method fd --fd-step 0", r"--fd-step must lie in \(0, 0.495\)", "CLI options"),
    BadCli("--fd-step with --method adjoint", f"{G} --fd-step 1e-5", "applies to --method fd", "CLI options"),
    BadCli("--json to a missing directory", f"{G} --json {{tmp}}/missing/psi.json", "does not exist",
           "CLI output paths"),
    BadCli("--json to a directory", f"{G} --json {{tmp}}", "is a directory", "CLI output paths"),
    BadCli("--plot to a missing directory", f"{G} --plot {{tmp}}/missing/g.png", "does not exist", "CLI output paths"),
    BadCli("--plot to a directory", f"{G} --plot {{tmp}}", "is a directory", "CLI output paths"),
    BadCli("--plot with an unknown format", f"{G} --plot {{tmp}}/g.xyz", "unknown image format", "CLI output paths"),
    BadCli("--nx 3", "gradient slider-crank --nx 3", "nx", "slider_crank()"),
    BadCli("--value 1.5", f"{G} --value 1.5", r"--value must lie in \[0.01, 1\]", "CLI options"),
    BadCli("optimize --volume 2", f"{O} --volume 2 --out {{tmp}}/o1", r"--volume must lie in \(0.01, 1\]",
           "CLI options"),
    BadCli("optimize --lr -1", f"{O} --lr -1 --out {{tmp}}/o2", "--lr must be positive", "CLI options"),
    BadCli("optimize --filter-radius inf", f"{O} --filter-radius inf --out {{tmp}}/o3", "--filter-radius must be finite",
           "CLI options"),
    BadCli("optimize --projection-beta -1", f"{O} --projection-beta -1 --out {{tmp}}/o4", "--projection-beta must be",
           "CLI options"),
    BadCli("optimize --iters -1", f"{O.replace('--iters 1', '--iters -1')} --out {{tmp}}/o5", "--iters must be",
           "CLI options"),
    BadCli("optimize --checkpoint-every 0", f"{O} --checkpoint-every 0 --out {{tmp}}/o6", "--checkpoint-every must be",
           "CLI options"),
    BadCli("optimize --out a file", f"{O} --out {{setup}}", "is a file, not a directory", "CLI output paths",
           lambda c: _file(c.tmp / "a_file")),
    BadCli("--resume a checkpoint with NaN design", f"{O} --resume {{setup}}", "checkpoint.npz holds a design with NaN",
           "load_checkpoint() (CLI)", lambda c: c.checkpoint("cli_nan", x=[0.5, NAN, 0.5, 0.5])),
    BadCli("--resume a checkpoint with density 0.005", f"{O} --resume {{setup}}",
           r"holds a design with densities outside \[0.01, 1", "load_checkpoint() (CLI)",
           lambda c: c.checkpoint("cli_low", x=[0.5, 0.005, 0.5, 0.5])),
    BadCli("--resume a checkpoint with inf optimizer state", f"{O} --resume {{setup}}", "NaN or inf in optimizer state",
           "load_checkpoint() (CLI)", lambda c: c.checkpoint("cli_state", leaves=(np.array([INF]),))),
    BadCli("--resume a truncated checkpoint", f"{O} --resume {{setup}}", "corrupt or incomplete",
           "load_checkpoint() (CLI)", lambda c: c.truncated_checkpoint("cli_cut")),
    BadCli("--resume with another --volume", "optimize slider-crank --volume 0.3 --resume {setup}",
           "the run was made with --volume 0.5", "CLI options", lambda c: c.checkpoint("cli_conflict")),
]

CLI_32 = [
    # Silently wrong before: the resumed run was the checkpoint's scene (slider-crank), whatever the command named.
    BadCli("--resume a slider-crank run as link-four-bar", "optimize link-four-bar --resume {setup}",
           "holds a run of slider-crank, not link-four-bar; resume it with ffr-jax optimize slider-crank --resume",
           "CLI settings", lambda c: c.checkpoint("cli_other_scene")),
    BadCli("--resume a slider-crank run as four-bar-two-links", "optimize four-bar-two-links --resume {setup}",
           "holds a run of slider-crank, not four-bar-two-links", "CLI settings",
           lambda c: c.checkpoint("cli_other_scene_2")),
    # Silently wrong before: nan > 0 is false, so the mass bound was dropped; --out '' wrote into the current folder.
    BadCli("optimize --mass-max nan", f"{O} --optimizer mma --mass-max nan --out {{tmp}}/o7", "--mass-max must be finite",
           "CLI settings"),
    BadCli("optimize --frequency-min -5", f"{O} --optimizer mma --frequency-min -5 --out {{tmp}}/o8",
           r"--frequency-min must be >= 0", "CLI settings"),
    BadCli("optimize --mma-move 2", f"{O} --optimizer mma --mma-move 2 --out {{tmp}}/o9", r"--mma-move must lie in \(0, 1\]",
           "CLI settings"),
    BadCli("optimize --out ''", f"{O} --out=", "--out '' names no directory", "CLI settings"),
    BadCli("optimize --force-resume without --resume", f"{O} --force-resume --out {{tmp}}/o10",
           "--force-resume applies to --resume", "CLI settings"),
    # numpy's "allow_pickle" advice before.
    BadCli("export --design garbage.npz", "export slider-crank --design {setup}/garbage.npz --svg {tmp}/g.svg",
           "garbage.npz is not a design file .* pass the design.npz written by `ffr-jax optimize`", "CLI settings",
           lambda c: _garbage_npz(c.tmp)),
]
CLI_32 += [
    # An OSError after the whole gradient was computed before: the directory is tried (a file created and removed)
    # with the other options. /sys takes no new files, for root too, as a read-only file system (where
    # os.access says yes for root).
    BadCli("--json where no file can be created (/sys)", f"{G} --json /sys/psi.json",
           r"--json /sys/psi.json: cannot create a file in /sys \(.*\); choose a directory you can write to",
           "CLI output paths"),
    BadCli("gradient --max-steps 0", f"{G} --max-steps 0", r"max_steps of the CLI \(--max-steps\) must be an integer >= 1",
           "CLI options"),
    BadCli("--plot where no file can be created (/sys)", f"{G} --plot /sys/g.png", "cannot create a file in /sys",
           "CLI output paths"),
]
CLI += CLI_32


def _garbage_npz(tmp: Path) -> Path:
    (tmp / "garbage.npz").write_bytes(b"garbage")
    return tmp


def _file(path: Path) -> Path:
    path.write_text("not a directory")
    return path


def run_cli(ctx: Ctx, bad: BadCli) -> tuple[int, str, str]:
    """`ffr-jax ARGV` in this process: `(exit status, stdout, stderr)` (argparse's own errors included)."""
    from ffr_jax._app._cli import main

    setup = bad.setup(ctx) if bad.setup is not None else None
    argv = bad.argv.format(tmp=ctx.tmp, setup=setup).split()
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code
    return status, out.getvalue(), err.getvalue()


def strict_json_of(record) -> str:
    """What the CLI writes: strict JSON (no bare NaN), or a clear `ValueError`."""
    from ffr_jax._app._cli_checks import finite_record

    return json.dumps(finite_record(record, "--json out.json"), allow_nan=False)


def timed(fn) -> tuple[float, BaseException | None, Any]:
    start = time.perf_counter()
    try:
        result = fn()
        return time.perf_counter() - start, None, result
    except BaseException as err:  # noqa: BLE001 - the point is to record whatever is raised
        return time.perf_counter() - start, err, None


def finite(tree) -> bool:
    return all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree_util.tree_leaves(tree))
