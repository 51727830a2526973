"""The design gradient as cacheable programs (`ffr_jax._app._cacheable`, what `ffr-jax gradient` runs).

Checked on the small case family: the split programs give the adjoint gradient of `value_and_grad`;
an exported program saved by one compilation is loaded by the next without tracing and gives the
same numbers bit for bit; equinox's checks raise again after the `nan`-mode tracing; a static part
without a stable name is never keyed.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ATOL, RTOL, adjoint_value_and_grad, random_design, small_case

import ffr_jax as fj
from ffr_jax._app._cacheable import _program_key, compile_value_and_grad


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    case = small_case()
    x = random_design(case, 0)
    directory = tmp_path_factory.mktemp("programs")
    fun, info = compile_value_and_grad(case, x, fj.Adjoint(), rtol=RTOL, atol=ATOL, export_dir=directory)
    return case, x, directory, fun, info


def test_split_programs_give_the_adjoint_gradient(compiled):
    case, x, directory, fun, info = compiled
    assert not info["exported_loaded"], "nothing to load on the first compilation"
    assert len(list(directory.glob("*.jaxexport"))) == 1, "the scene-gradient program is saved"
    psi, grad = fun(x)
    psi_ref, grad_ref = adjoint_value_and_grad(case, x)
    # The same computation (the design gradient is the scene gradient pulled back through the design
    # map: `AbstractSensitivity.value_and_grad_design`) compiled as other programs: XLA may order
    # floating-point sums differently, and the adaptive step control can turn that round-off into
    # another step sequence, so the two agree to the solves' accuracy: forward rtol 1e-10 (psi:
    # allowed 1e-9), backward rtol 1e-8 (gradient: allowed 1e-7 relative, max-norm).
    np.testing.assert_allclose(float(psi), float(psi_ref), rtol=1e-9)
    assert np.max(np.abs(grad - grad_ref)) <= 1e-7 * np.max(np.abs(grad_ref)), "gradient vs value_and_grad"


def test_a_saved_program_is_loaded_without_tracing(compiled):
    case, x, directory, fun, _ = compiled
    jax.clear_caches()
    again, info = compile_value_and_grad(case, x, fj.Adjoint(), rtol=RTOL, atol=ATOL, export_dir=directory)
    assert info["exported_loaded"], "the second compilation loads the exported program"
    x2 = random_design(case, 1)
    # The same StableHLO compiled by the same XLA on the same machine: bit-identical results.
    for a, b in zip(jax.tree_util.tree_leaves(fun(x2)), jax.tree_util.tree_leaves(again(x2))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_checks_raise_again_after_nan_mode_tracing(compiled):
    # `compiled` traced the scene gradient with equinox's checks as NaN; a new trace must raise.
    f = eqx.filter_jit(lambda v: eqx.error_if(v, v < 0, "negative"))
    with pytest.raises(eqx.EquinoxRuntimeError, match="negative"):
        jax.block_until_ready(f(jnp.asarray(-1.0)))


def _named(t):
    return t


def test_a_lambda_in_the_static_part_is_never_keyed():
    leaves, treedef = jax.tree_util.tree_flatten(jnp.zeros(3))
    assert _program_key((_named,), treedef, leaves, {}) is not None, "a named function has a stable key"
    assert _program_key((lambda t: t,), treedef, leaves, {}) is None, "a lambda has none"
