"""Bad input to the dynamics: each a clear error that names the problem, never a silent NaN.

Inconsistent initial conditions, a coordinate partition that is singular, Newton's method without
a solution, and diffrax running out of steps — through `simulate` and through the model.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax
from ffr_jax._dynamics._model import Partition


@pytest.fixture(scope="module")
def pendulum():
    case = ffr_jax.cases.flexible_pendulum(6, 2, 2, t1=0.05)
    return case, eqx.filter_jit(case.scene)(case.initial_design(0.5))


def _simulate(case, scene, y_r0=None, z_r0=None, **kwargs):
    y_r0 = case.y_r0 if y_r0 is None else y_r0
    z_r0 = case.z_r0 if z_r0 is None else z_r0
    return ffr_jax.simulate(case.model, scene, case.t0, case.t1, y_r0, z_r0, **kwargs)


def test_inconsistent_initial_positions(pendulum):
    case, scene = pendulum
    y_r0 = case.y_r0.at[0].set(0.01)  # the pinned point A moved off its pivot
    with pytest.raises(eqx.EquinoxRuntimeError, match="initial positions violate the position constraints"):
        _simulate(case, scene, y_r0=y_r0)


def test_inconsistent_initial_velocities(pendulum):
    case, scene = pendulum
    z_r0 = case.z_r0.at[1].set(0.5)  # the pivot moving upwards
    with pytest.raises(eqx.EquinoxRuntimeError, match="initial velocities violate the velocity constraints"):
        _simulate(case, scene, z_r0=z_r0)


def test_initial_state_of_the_wrong_shape(pendulum):
    case, scene = pendulum
    with pytest.raises(ValueError, match="must have shape"):
        _simulate(case, scene, y_r0=case.y_r0[:-1])


def test_diffrax_out_of_steps(pendulum):
    case, scene = pendulum
    with pytest.raises(eqx.EquinoxRuntimeError, match="max_steps"):
        _simulate(case, scene, max_steps=3, rtol=1e-12, atol=1e-14)


# --- a slider–crank whose slider position is taken as independent coordinate ------------------------
ECC, LENGTH = 0.1, 0.4


def _assembled(phi: float):
    """Redundant positions of the rigid slider–crank assembled at crank angle `phi`."""
    beta = -np.arcsin(ECC * np.sin(phi) / LENGTH)
    x_b = ECC * np.cos(phi) + LENGTH * np.cos(beta)
    return np.array([0.0, 0.0, phi, ECC * np.cos(phi), ECC * np.sin(phi), beta, x_b, 0.0, 0.0])


def _slider_independent(phi: float = 1.2):
    """Free rigid slider–crank with the slider's `x` (coordinate 6) independent, crank angle dependent,
    assembled at crank angle `phi`.

    At the dead points (`phi = 0, pi`) the crank angle is not a function of the slider position:
    the partition is singular there.
    """
    base = ffr_jax.cases.rigid_slider_crank(driven=False, eccentricity=ECC, length=LENGTH)
    partition = Partition(independent=(6,), dependent=(0, 1, 2, 3, 4, 5, 7, 8))
    return ffr_jax.Problem(base.scene, base.t1, positions=_assembled(phi), partition=partition,
                           objective=ffr_jax.KineticEnergy())


def test_singular_partition_is_an_error_not_a_nan():
    # A problem that starts at the dead point (phi = 0) is refused when it is built...
    with pytest.raises(ValueError, match="singular"):
        _slider_independent(phi=0.0)
    # ... and Newton's method started at the dead point stops with the singular-partition error.
    case = _slider_independent()
    dead = jnp.asarray(_assembled(0.0)[np.asarray(case.model.partition.dependent)])
    case = eqx.tree_at(lambda c: c.model.reference_dependent, case, dead)
    with pytest.raises(eqx.EquinoxRuntimeError, match="coordinate partition became singular"):
        # (Compiled as one program: eagerly, the checks compile op by op.)
        eqx.filter_jit(case.model.dependent_positions)(jnp.asarray(0.0), jnp.array([ECC + LENGTH]), case.scene)


def test_partition_regular_away_from_the_dead_point():
    """The same partition works where it is regular: the slider position gives the crank angle."""
    case = _slider_independent()
    x_s = 0.42
    y_d = case.model.dependent_positions(jnp.asarray(0.0), jnp.array([x_s]), case.scene)
    y_r = case.model.assemble(jnp.array([x_s]), y_d)
    phi = float(y_r[2])
    closed_form = ECC * np.cos(phi) + np.sqrt(LENGTH**2 - (ECC * np.sin(phi)) ** 2)
    np.testing.assert_allclose(closed_form, x_s, rtol=1e-12)
    assert float(jnp.max(jnp.abs(case.scene.constraint_residual(jnp.asarray(0.0), y_r)))) < 1e-12


def test_newton_without_solution_is_an_error():
    """A slider position the linkage cannot reach (`x_s < l - eps`): Newton fails, and says so."""
    case = _slider_independent()
    with pytest.raises(eqx.EquinoxRuntimeError, match="did not converge"):
        # Compiled as one program: run eagerly, Newton's loop and its checks dispatched op by op (26 s here).
        eqx.filter_jit(case.model.dependent_positions)(jnp.asarray(0.0), jnp.array([0.5 * (LENGTH - ECC)]),
                                                       case.scene)
