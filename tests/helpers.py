"""Shared test helpers: the small member of the slider–crank family, and pytree comparison."""

import functools

import jax
import jax.numpy as jnp
import numpy as np

import ffr_jax


@functools.cache
def small_case(nx: int = 12, ny: int = 2, n_modes: int = 4, t1: float = 0.2) -> ffr_jax.FlexibleRodCase:
    """A small slider–crank (REFERENCE_CASE §5), built once per session for each argument set."""
    return ffr_jax.cases.slider_crank(nx, ny, n_modes, t1)


def random_design(case: ffr_jax.FlexibleRodCase, seed: int, low: float = 0.2, high: float = 0.95) -> jax.Array:
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
