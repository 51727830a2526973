"""Two designed bodies in one mechanism (issue 14): the crank–rocker with a flexible coupler AND rocker.

One small case (8 x 2 coupler, 6 x 2 rocker, 2 modes each, t1 = 0.3 s of the crank's run-up) serves
every test through a module-scoped fixture. By default: one adjoint compile and one forward compile
(the finite differences). Marked slow (each another compile of a whole gradient program, minutes on
a loaded 2-core machine): adjoint = autodiff, and the rocker frozen = the one-body case (that one is
also a row of benchmarks/bench_two_bodies.py on a larger case).
"""

import diffrax
import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
import ffr_jax._design as fd

# psi is about 1.6e-6 and the elastic coordinates about 1e-6, so the forward solves run at atol
# 1e-15 (the default 1e-12 would be 1e-6 of the coordinates) and the adjoint's backward solve at
# rtol 1e-10, atol 1e-15, as for the double pendulum of test_design_map.py.
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-15)
RTOL, ATOL = 1e-10, 1e-15
FD_STEP = 1e-4
T1 = 0.3


def _case(**kwargs):
    return fj.cases.four_bar_two_links(8, 2, 2, T1, modal_solver=fd.DenseModes(), **kwargs)


def _designs(case, seed):
    rng = np.random.default_rng(seed)
    return {name: jnp.asarray(rng.uniform(0.3, 0.9, n)) for name, n in case.design_map.design_sizes.items()}


@pytest.fixture(scope="module")
def two_links():
    """The two-body case, a design, its adjoint `(psi, grad)`, and the number of diffrax solves traced."""
    case = _case()
    x = _designs(case, 0)
    solves = []
    original = diffrax.diffeqsolve

    def counting(*args, **kwargs):
        solves.append(1)
        return original(*args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(diffrax, "diffeqsolve", counting)
        psi, grad = fj.value_and_grad(case, x, ADJOINT, rtol=RTOL, atol=ATOL)
    return case, x, float(psi), jax.tree_util.tree_map(np.asarray, grad), len(solves)


def _body_error(got, want):
    """`max |got - want| / max |want|` of one body's gradient."""
    return float(np.max(np.abs(got - want)) / np.max(np.abs(want)))


def test_the_case_designs_both_rods_with_their_own_meshes_and_modes(two_links):
    case, x, psi, grad, solves = two_links
    dmap = case.design_map
    assert dmap.names == ("coupler", "rocker")
    assert dmap.design_sizes == {"coupler": 6 * 2, "rocker": 4 * 2}, "8 x 2 and round(8 * 0.8) = 6 x 2, end columns solid"
    assert dmap.bodies["coupler"].mesh is not dmap.bodies["rocker"].mesh
    assert dmap.bodies["coupler"].n_modes == dmap.bodies["rocker"].n_modes == 2
    assert case.model.partition.independent == (6, 7, 11, 12), "independent: q_coupler, q_rocker"
    assert psi > 0.0 and set(grad) == {"coupler", "rocker"}
    for name in grad:
        assert grad[name].shape == x[name].shape and np.all(np.isfinite(grad[name]))
        assert np.max(np.abs(grad[name])) > 0.0, f"the motion must depend on the {name}'s design"


def test_both_gradients_by_one_forward_and_one_backward_solve(two_links):
    assert two_links[4] == 2, f"value_and_grad traced {two_links[4]} diffrax solves; one forward and one backward expected"


@pytest.mark.slow  # an autodiff compile (forward mode); FD below checks the same gradient by default
def test_adjoint_equals_autodiff_on_each_body(two_links):
    """Autodiff is the exact derivative of the discrete psi (rtol 1e-10, atol 1e-15); the adjoint
    solves the continuous adjoint ODE at rtol 1e-10 and integrates the gradient quadrature with it.
    Each differs from the exact gradient by the solver error, ~1e-10 of the solution amplified by the
    adjoint's sensitivity to it; the double pendulum at these tolerances agreed to 1e-7 of max |grad|.
    We allow 1e-6 per body, i.e. relative to each body's own largest entry (the coupler's gradient is
    ~100x smaller than the rocker's, so a global scale would not test it)."""
    case, x, psi, grad, _ = two_links
    # Automatic differentiation in forward mode (`jax.jacfwd` through the solver, diffrax's `ForwardMode`) along the
    # 20 densities: the exact derivative of the discrete psi that `jax.grad` through the solver (`"autodiff"`) gives,
    # without compiling the reverse pass: 58.4 s -> 34.3 s on one quiet core.
    flat, unravel = jax.flatten_util.ravel_pytree(x)

    def psi_of(y):
        value = fj.simulate(case, unravel(y), rtol=RTOL, atol=ATOL, adjoint=diffrax.ForwardMode()).psi
        return value, value

    g_flat, psi_ad = jax.jit(jax.jacfwd(psi_of, has_aux=True))(flat)
    grad_ad = unravel(g_flat)
    assert abs(float(psi_ad) - psi) <= 1e-9 * psi, "the same forward solve"
    for name in ("coupler", "rocker"):
        err = _body_error(grad[name], np.asarray(grad_ad[name]))
        assert err <= 1e-6, f"{name}: adjoint vs autodiff {err:.2e} of max |grad|"


def test_adjoint_equals_finite_differences_on_entries_of_each_body(two_links):
    """Central differences, step 1e-4, of psi at rtol 1e-12 / atol 1e-16 on densities in [0.3, 0.9]:
    truncation h^2/6 |d3 psi / dx3| ~ 1e-8 |grad| (the SIMP law is a cubic in x, smooth here), the
    solver's error (1e-12 psi ~ 2e-18 absolute; step-sequence changes with x add at most the same)
    over 2h gives ~1e-14, i.e. ~1e-8 of the coupler's max |grad| (1e-6); plus the adjoint's own error
    (<= 1e-6, above). Tolerance 1e-5 of each body's max |grad|: an order above that sum."""
    case, x, psi, grad, _ = two_links
    objective = eqx.filter_jit(lambda case, x: fj.objective(case, x, rtol=1e-12, atol=1e-16))
    assert abs(float(objective(case, x)) - psi) <= 1e-8 * psi, "psi at rtol 1e-12 and 1e-10"
    for name in ("coupler", "rocker"):
        scale = np.max(np.abs(grad[name]))
        for e in np.argsort(-np.abs(grad[name]))[:2]:
            plus = {**x, name: x[name].at[e].add(FD_STEP)}
            minus = {**x, name: x[name].at[e].add(-FD_STEP)}
            fd_ = float(objective(case, plus) - objective(case, minus)) / (2 * FD_STEP)
            assert abs(grad[name][e] - fd_) <= 1e-5 * scale, \
                f"d psi / d x[{name!r}][{e}]: adjoint {grad[name][e]:.6e}, central differences {fd_:.6e}"


@pytest.mark.slow  # another adjoint compile (6.2 min cold at load 11); also a row of bench_two_bodies.py
def test_rocker_frozen_equals_the_one_body_case(two_links):
    """The two-body case at (x_c, x_r) and the one-body case of the same mechanism with the rocker
    frozen at x_r (its data computed once when the case is built; only the coupler designed) solve the
    same equations with the same numbers: psi and the coupler's gradient agree to round-off, up to
    the solver's step sequence reacting to it (a step accepted or rejected differently moves the
    result by at most the tolerance, 1e-10 of psi). We allow 1e-9 relative."""
    case, x, psi, grad, _ = two_links
    one = _case(designed=("coupler",), frozen={"rocker": x["rocker"]})
    assert one.design_map.names == ("coupler",) and one.n_design == x["coupler"].size
    psi_1, grad_1 = fj.value_and_grad(one, x["coupler"], ADJOINT, rtol=RTOL, atol=ATOL)
    assert abs(float(psi_1) - psi) <= 1e-9 * psi, f"psi: one body {float(psi_1):.15e}, two bodies {psi:.15e}"
    err = _body_error(np.asarray(grad_1), grad["coupler"])
    assert err <= 1e-9, f"coupler gradient, one body vs two: {err:.2e} of max |grad|"


def test_bad_designs_name_the_body(two_links):
    case, x, *_ = two_links
    with pytest.raises(ValueError, match=r"no entry for the designed body 'rocker'"):
        fj.value_and_grad(case, {"coupler": x["coupler"]})
    with pytest.raises(ValueError, match=r"entries for 'crank', which is not a designed body"):
        fj.value_and_grad(case, {**x, "crank": x["rocker"]})
    with pytest.raises(ValueError, match=r"expected \(8,\) for body 'rocker'"):
        fj.value_and_grad(case, {**x, "rocker": jnp.full(12, 0.5)})
    with pytest.raises(ValueError, match=r"2 designed bodies \['coupler', 'rocker'\]: pass the design as a dict"):
        fj.value_and_grad(case, jnp.full(case.n_design, 0.5))
    with pytest.raises(ValueError, match=r"designed must name one or both"):
        _case(designed=("crank",))
    with pytest.raises(ValueError, match=r"frozen names \['coupler'\]"):
        _case(frozen={"coupler": x["coupler"]})
    with pytest.raises(ValueError, match=r"expected \(8,\) for body 'rocker'"):
        _case(designed=("coupler",), frozen={"rocker": jnp.full(3, 0.5)})
