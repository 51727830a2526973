"""The derivative of the minimal accelerations through the equations of motion (implicit function
theorem on the matrix-free residual) against differentiating through their solution."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from helpers import small_case


@pytest.mark.parametrize("n_modes", [3, 14], ids=["unrolled", "lapack"])
def test_custom_derivative_of_accelerations_equals_the_direct_one(n_modes):
    # Both are the exact derivative of the same function, evaluated in another order; they differ
    # by rounding amplified by cond(Mbar) (about 1e3 here), measured at 1e-16..1e-14 of the largest
    # entry, so 1e-11 leaves three orders. 14 modes takes the LAPACK path of the linear algebra.
    case = small_case(10, 2, n_modes, 0.2)
    model, scene = case.model, case.scene(case.initial_design(0.5))
    f = model.partition.n_independent
    t, y, z = jnp.asarray(0.7), 1e-4 * jnp.arange(1.0, f + 1), 1e-2 * jnp.ones(f)

    def custom(t, y, z, s):
        return model.state_and_accelerations(t, y, z, s)

    def direct(t, y, z, s):
        return model._state_and_accelerations(t, y, z, s)

    def close(a, b, what):
        scale = float(jnp.max(jnp.abs(b)))
        assert float(jnp.max(jnp.abs(a - b))) <= 1e-11 * scale, what

    # The values: `custom` runs compiled (the equations of motion sit behind a jit boundary), `direct` op by op, so
    # XLA may round differently (measured 1.8e-16 relative); the same bound as the derivatives.
    for k, (a, b) in enumerate(zip(custom(t, y, z, scene), direct(t, y, z, scene))):
        close(a, b, f"output {k}")
    # Compiled, not run op by op: eager dispatch of the Jacobians' thousands of small operations cost
    # about a minute per parametrisation on two cores; one compiled program each takes seconds.
    jac_custom = eqx.filter_jit(jax.jacfwd(custom, argnums=(0, 1, 2)))(t, y, z, scene)
    jac_direct = eqx.filter_jit(jax.jacfwd(direct, argnums=(0, 1, 2)))(t, y, z, scene)
    for out in range(3):
        for arg in range(3):
            close(jac_custom[out][arg], jac_direct[out][arg], f"d output {out} / d argument {arg}")

    def energy(fn):
        return eqx.filter_jit(eqx.filter_grad(lambda s: jnp.sum(fn(t, y, z, s)[2] ** 2)))(scene)

    for a, b in zip(jax.tree_util.tree_leaves(energy(custom)), jax.tree_util.tree_leaves(energy(direct))):
        close(a, b, "reverse-mode derivative with respect to the scene")


@pytest.mark.slow
def test_second_derivatives_of_accelerations_by_both_orders_of_differentiation():
    # Second derivatives of the accelerations with respect to the state, as the discrete adjoint of a
    # Rosenbrock step and `jax.grad` through it form them (reverse mode over the forward-mode rule of
    # `state_and_accelerations`), and as a Hessian by `jax.jacfwd` of `jax.grad` forms them (forward
    # mode over the transposed rule). The tangent solve of the rule (`factored_solve`) is differentiated
    # through its own rule in the first route and through the elimination in the second: with its
    # factors held constant (`stop_gradient`) the second was 1.04 off here (4.6e-5 in a step of the
    # reference case). Both are exact, and the first derivatives they build on are checked against the
    # direct route above; they differ by rounding amplified by cond(Mbar) twice, measured 2e-16 of the
    # largest entry (each also 2e-16 from differentiating the direct route twice, not compiled here);
    # 1e-10 leaves six orders for other platforms, a missing term is O(1). Slow (8.6 s, the suite's
    # 8-minute budget); `factored_solve` in both orders is tests/test_small_linalg.py, default suite.
    case = small_case(10, 2, 3, 0.2)
    model, scene = case.model, case.scene(case.initial_design(0.5))
    f = model.partition.n_independent
    t, y, z = jnp.asarray(0.7), 1e-4 * jnp.arange(1.0, f + 1), 1e-2 * jnp.ones(f)
    weights = jnp.linspace(0.5, 1.5, f)

    def power(u):
        return weights @ model.state_and_accelerations(t, u[:f], u[f:], scene)[2]

    @jax.jit
    def hessian_vector_products(u, v):
        reverse_over_forward = jax.grad(lambda x: jax.jvp(power, (x,), (v,))[1])(u)
        forward_over_reverse = jax.jvp(jax.grad(power), (u,), (v,))[1]
        return reverse_over_forward, forward_over_reverse

    rof, for_ = hessian_vector_products(jnp.concatenate([y, z]), jnp.cos(jnp.arange(2.0 * f)))
    scale = float(jnp.max(jnp.abs(rof)))
    assert scale > 0
    assert float(jnp.max(jnp.abs(rof - for_))) <= 1e-10 * scale
