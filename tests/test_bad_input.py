"""Bad input to the foundation (mesh, design, modal reduction) fails early with a message naming it."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import small_case

import ffr_jax

# eqx.error_if raises EquinoxRuntimeError eagerly and under eqx.filter_jit, and a
# jax.errors.JaxRuntimeError carrying the same message under jax.jit; both are RuntimeErrors.
RUNTIME_ERRORS = (eqx.EquinoxRuntimeError, RuntimeError)
CALLS = {"eager": lambda f: f, "filter_jit": eqx.filter_jit, "jit": lambda f: jax.jit(lambda x: f(x))}


@pytest.fixture(scope="module")
def case():
    return small_case()


@pytest.mark.parametrize("length_change", [-1, 1])
def test_design_of_wrong_length(case, length_change):
    x = jnp.full(case.n_design + length_change, 0.5)
    with pytest.raises(ValueError, match=rf"Design vector has shape \({case.n_design + length_change},\), expected"):
        case.fe_matrices(x)
    # At trace time: no computation is needed to see it, and the message names the designed body.
    with pytest.raises(ValueError, match=rf"expected \({case.n_design},\) for body 'rod'"):
        jax.eval_shape(case.frequencies, x)


@pytest.mark.parametrize("call", list(CALLS))
def test_nan_in_design(case, call):
    x = case.initial_design(0.5).at[3].set(jnp.nan)
    with pytest.raises(RUNTIME_ERRORS, match="Design vector contains NaN"):
        jax.block_until_ready(CALLS[call](case.frequencies)(x))


@pytest.mark.parametrize("value", [0.0, 0.005, 1.5, -0.2])
def test_density_outside_bounds(case, value):
    x = case.initial_design(0.5).at[5].set(value)
    with pytest.raises(RUNTIME_ERRORS, match=r"must lie in \[x_min, 1\]"):
        jax.block_until_ready(case.fe_matrices(x))
    with pytest.raises(RUNTIME_ERRORS, match=r"must lie in \[x_min, 1\]"):
        jax.block_until_ready(eqx.filter_jit(case.body_data)(x))


def test_initial_design_outside_bounds(case):
    with pytest.raises(ValueError, match=r"outside \[x_min, 1\]"):
        case.initial_design(1.5)


@pytest.mark.parametrize("ny", [1, 3, 5])
def test_odd_ny(ny):
    with pytest.raises(ValueError, match="ny must be even"):
        ffr_jax.cases.rod_body(10, ny, 2)
    with pytest.raises(ValueError, match="ny must be even"):
        ffr_jax.cases.slider_crank(10, ny, 2, 0.1)


def test_mesh_too_short_or_not_int():
    with pytest.raises(ValueError, match="nx must be at least 4"):
        ffr_jax.cases.rod_body(3, 2, 2)
    # The library's ValueError, or jaxtyping's TypeCheckError (a TypeError) when the hook is on.
    with pytest.raises((ValueError, TypeError), match="nx"):
        ffr_jax.cases.rod_body(10.0, 2, 2)


def test_too_many_modes():
    """The 4 x 2 rod has 30 degrees of freedom, 3 held: at most 26 modes (the derivative of the
    retained subspace needs a discarded mode)."""
    n_free = 2 * 5 * 3 - 3
    x = jnp.full(2 * 2, 0.5)
    for n_modes in (n_free, n_free + 5):
        body = ffr_jax.cases.rod_body(4, 2, n_modes, modal_solver=ffr_jax.DenseModes())
        with pytest.raises(ValueError, match=rf"n_modes={n_modes} must be a positive int smaller than the number of "
                                             rf"interior degrees of freedom \({n_free}\)"):
            body.frequencies(x)
    with pytest.raises(ValueError, match="n_modes must be a positive int"):
        ffr_jax.cases.rod_body(4, 2, 0)
    with pytest.raises(ValueError, match="smaller than the number of interior degrees of freedom"):
        ffr_jax.cases.slider_crank(4, 2, n_free, 0.1)
    # One mode fewer than the free dofs is the largest valid choice.
    body = ffr_jax.cases.rod_body(4, 2, n_free - 1, modal_solver=ffr_jax.DenseModes())
    assert np.all(np.isfinite(np.asarray(body.modes(x).modes)))
