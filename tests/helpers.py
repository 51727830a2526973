"""Shared test helpers: the small case family and its compiled programs, and comparisons.

Compiling a diffrax solve and its gradient takes seconds to tens of seconds on a 2-core machine
and dominates the suite (an adjoint gradient: about 15 s; a forward objective: about 3 s); JAX's
persistent cache does not help, since programs with host callbacks (every `eqx.error_if`, so every
diffrax solve) are never written to it. The suite therefore uses one structure for every
simulation-based check of the slider–crank, `FAMILY` (REFERENCE_CASE §5: 12 x 2 elements, 4 modes,
a 0.05 s crank run-up and 0.1 s at full speed), and the programs below are compiled once per
process and per case *structure*: they take the case as an argument (`eqx.filter_jit`), so every
test module, and every variant of the family with other array values (`hard_cases.variant`: other
crank radius or speed), reuses them. Under pytest-xdist the modules that share them run in one
worker (`tests/conftest.py`).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax

# The family member every simulation-based check uses (the hard-case base of benchmarks/bench_hard_cases.py).
# The one list of gradient methods (the names `fj.value_and_grad` takes) that every agreement test loops
# over; tests/test_sensitivity.py checks that it is the package's whole list.
GRADIENT_METHODS = ("adjoint", "autodiff", "backsolve", "direct", "discrete-adjoint", "fd")

FAMILY = dict(nx=12, ny=2, n_modes=4, t1=0.15, t_ramp=0.05)

# Forward tolerances of every gradient (the paper's), and of the finite-difference evaluations: two
# decades tighter, so that the difference quotient is not dominated by solver noise.
RTOL, ATOL = 1e-10, 1e-12
FD_RTOL, FD_ATOL = 1e-12, 1e-14

# How often each shared program was traced in this process (a Python side effect, run at trace time only).
TRACES: dict[str, int] = {}


@functools.cache
def small_case(nx: int = FAMILY["nx"], ny: int = FAMILY["ny"], n_modes: int = FAMILY["n_modes"],
               t1: float = FAMILY["t1"], t_ramp: float = FAMILY["t_ramp"], **options) -> ffr_jax.Case:
    """A member of the slider–crank family (REFERENCE_CASE §5), `FAMILY` by default, built once per process."""
    return ffr_jax.cases.slider_crank(nx, ny, n_modes, t1, t_ramp=t_ramp, **options)


def _count(name: str) -> None:
    TRACES[name] = TRACES.get(name, 0) + 1


@eqx.filter_jit
def adjoint_value_and_grad(case, x):
    """`(psi, grad psi)` by the paper's adjoint method with the default settings of `value_and_grad`
    (forward rtol 1e-10 / atol 1e-12, backward 1e-8 / 1e-10), compiled once per case structure."""
    _count("adjoint")
    return ffr_jax.value_and_grad(case, x, "adjoint", rtol=RTOL, atol=ATOL)


@eqx.filter_jit
def tight_objective(case, x):
    """`psi(x)` at the tolerances of the finite-difference checks (rtol 1e-12), compiled once per structure."""
    _count("objective")
    return ffr_jax.objective(case, x, rtol=FD_RTOL, atol=FD_ATOL)


def central_difference(f, h: float):
    """Fourth-order central difference of a scalar function of one real at 0 (four evaluations).

    Error `h^4 |f^(5)| / 30` plus `3 delta / (2 h)` for evaluations accurate to `delta`. Second
    order is not enough next to low densities: `E ~ x^3` and `rho ~ x^6` make the third
    derivative of `psi` large, and a two-point quotient with `h = 1e-4` is off by ~1e-5 there.
    """
    return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h)


def uniform_design(case: ffr_jax.Case, value: float = 0.5) -> jax.Array:
    """`case.initial_design(value)` as a strongly typed float64 array.

    `initial_design` returns a weakly typed array (`jnp.full` of a Python float), and `jax.jit`
    compiles a separate program for weak and strong inputs: this keeps one program per structure.
    """
    return jnp.asarray(np.asarray(case.initial_design(value)))


def random_design(case: ffr_jax.Case, seed: int, low: float = 0.2, high: float = 0.95) -> jax.Array:
    """A reproducible random design with every entry in `[low, high]`, inside `[x_min, 1]`.

    The default range stays clear of the SIMP switch at `x = 0.1`, where the density law has a
    kink, so that finite differences see a smooth function.
    """
    rng = np.random.default_rng(seed)
    return jnp.asarray(rng.uniform(low, high, case.n_design))


def tree_allclose(a, b, rtol: float = 1e-12, atol: float = 0.0) -> bool:
    """Whether two pytrees have the same structure and leaf shapes, and all leaves are close."""
    leaves_a, tree_a = jax.tree_util.tree_flatten(a)
    leaves_b, tree_b = jax.tree_util.tree_flatten(b)
    if tree_a != tree_b:
        return False
    for x, y in zip(leaves_a, leaves_b):
        x, y = np.asarray(x), np.asarray(y)
        if x.shape != y.shape or not np.allclose(x, y, rtol=rtol, atol=atol):
            return False
    return True


def relative_error(actual, expected) -> float:
    """`max |actual - expected| / max |expected|` (the max-norm error relative to the quantity's size)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.max(np.abs(expected)) if expected.size else 0.0
    err = np.max(np.abs(actual - expected)) if expected.size else 0.0
    return float(err / scale) if scale > 0 else float(err)


def assert_close_relative(actual, expected, rtol: float, name: str) -> None:
    """`|actual - expected| <= rtol * max|expected|` elementwise, scaled by the quantity's size.

    Comparing against the largest entry (not entrywise) is the right measure for vectors and
    matrices whose small entries are the result of cancellation, such as off-diagonal terms.
    """
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, f"{name}: shape {actual.shape} != {expected.shape}"
    scale = np.max(np.abs(expected)) if expected.size else 0.0
    err = np.max(np.abs(actual - expected)) if expected.size else 0.0
    assert err <= rtol * scale, f"{name}: max error {err:.3e} exceeds {rtol:.0e} x scale {scale:.3e}"


def rotation(theta):
    """The planar rotation `A(theta)` written out independently of the library."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, -s], [s, c]])


def random_orthogonal(n: int, seed: int) -> np.ndarray:
    """A random orthogonal `(n, n)` matrix with determinant -1 (a rotation composed with a sign flip)."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(n, n)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) > 0:
        q[:, 0] = -q[:, 0]
    return q


def crank_arm_scene(stiffness: float = 200.0) -> ffr_jax.Scene:
    """The README's own mechanism: a driven rigid crank, a rigid arm hanging from its pin, a
    spring–damper from the arm's tip to the ground, a harmonic vertical force on the tip, gravity.

    One degree of freedom (the arm's angle). Tests that use it share its compiled programs with the
    README test, so keep the two identical.
    """
    crank = ffr_jax.Body("crank", ffr_jax.rigid_body_data(0.5, (0.025, 0.0), 0.5 * 0.1**2 / 3, [[0, 0], [0.1, 0]]))
    arm = ffr_jax.Body("arm", ffr_jax.rigid_body_data(1.0, (0.2, 0.0), 1.0 * 0.4**2 / 3, [[0, 0], [0.4, 0]]))
    return ffr_jax.Scene(
        bodies=(crank, arm),
        constraints=(
            ffr_jax.GroundRevolute(body=0, marker=0),
            ffr_jax.AngleDriver(body=0, angle=ffr_jax.RampLaw(t_ramp=0.5, angle_at_ramp=np.pi / 2, speed=2 * np.pi)),
            ffr_jax.Revolute(body_i=0, marker_i=1, body_j=1, marker_j=0),
        ),
        forces=(
            ffr_jax.SpringDamper(1, 1, stiffness=stiffness, damping=2.0, rest_length=0.3, ground_point=(0.3, -0.3)),
            ffr_jax.AppliedForce(1, 1, magnitude=ffr_jax.HarmonicLaw(5.0, 2.0), direction=(0.0, 1.0)),
            ffr_jax.Gravity(),
        ),
    )


CRANK_ARM_POSITIONS = (0.0, 0.0, 0.0, 0.1, 0.0, -np.pi / 2)  # crank along x, the arm hanging down
