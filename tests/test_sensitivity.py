"""Sensitivity analysis (issue 4, paper Sect. 3): the five gradient methods agree with each other and
with central finite differences on every entry; directional derivatives against `jax.jvp` and finite
differences; a design where two retained eigenvalues cross; `value_and_grad` under `jax.jit` (no
retracing) and `jax.vmap`; the gradient with respect to a scene parameter (the crank radius); bad
input; the `ffr-jax gradient` command.

Compiling a gradient program takes tens of seconds on a 2-core machine and dominates this module:
one small member of the slider–crank family (REFERENCE_CASE §5) serves every test, and each
compiled program is built once in a module-scoped fixture and reused by several tests (the direct
method's scene gradient, for instance, gives both its design gradient and the crank-radius check).
"""

import json

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from helpers import assert_close_relative, random_design, small_case

import ffr_jax as fj
from ffr_jax._cli import main

NX, NY, MODES, T1 = 12, 2, 3, 0.2
RTOL, ATOL = 1e-10, 1e-12  # forward tolerances of every solve (the paper's)
# Backward tolerances of the adjoint ODE: its states (mu, nu and the gradient accumulator) are of
# the size of psi (~1e-7 here), so the absolute tolerance must sit well below that.
ADJOINT = fj.Adjoint(rtol=1e-10, atol=1e-16)
BACKSOLVE = fj.Backsolve(rtol=1e-10, atol=1e-16)
# Central differences: truncation error ~ h^2 psi''' and solver noise ~ (rtol psi) / h balance near
# h ~ 1e-4 for densities of order 0.5 (a step study on this case gives 1e-6 relative agreement).
FD_STEP = 1e-4

# Agreement targets, relative to the largest entry of the reference gradient (max norm).
ADJOINT_VS_AUTODIFF = 1e-6  # issue 4: at tight tolerances
METHODS_AGREE = 1e-5  # backsolve and direct: continuous adjoint / forward mode at the same tolerances
FINITE_DIFFERENCES = 1e-4  # central differences, every entry


def _radius(scene):
    return scene.constraints[0].radius


@pytest.fixture(scope="module")
def case():
    return small_case(NX, NY, MODES, T1)


@pytest.fixture(scope="module")
def x(case):
    return random_design(case, 0)


@pytest.fixture(scope="module")
def psi_jvp_fn(case):
    """`(psi, dpsi/dx . v)` by `jax.jvp` of the forward objective, as a function of the design, the
    crank radius and a direction `v`: compiled once, for every finite difference (the tangent is then
    ignored) and the directional derivatives of the module."""

    def psi(x, radius):
        scene = eqx.tree_at(_radius, case.scene(x), radius)
        # The rod's point A starts at the crank pin: R_x(0) = radius keeps the initial state consistent.
        y_r0 = case.y_r0.at[0].set(radius)
        return fj.simulate(case.model, scene, case.t0, case.t1, y_r0, case.z_r0, integrand=case.integrand,
                           rtol=RTOL, atol=ATOL, jump_ts=case.jump_ts, adjoint=diffrax.ForwardMode()).psi

    return jax.jit(lambda x, radius, v: jax.jvp(lambda x: psi(x, radius), (x,), (v,)))


@pytest.fixture(scope="module")
def psi_fn(psi_jvp_fn):
    return lambda x, radius: psi_jvp_fn(x, radius, jnp.zeros_like(x))[0]


@pytest.fixture(scope="module")
def adjoint_traces():
    return []


@pytest.fixture(scope="module")
def adjoint_fn(case, adjoint_traces):
    """`jax.jit(value_and_grad(case, x, Adjoint))`, counting how often it is traced."""

    def value_and_grad(x):
        adjoint_traces.append(x.shape)
        return fj.value_and_grad(case, x, ADJOINT, rtol=RTOL, atol=ATOL)

    return jax.jit(value_and_grad)


@pytest.fixture(scope="module")
def method_fns(case):
    """Autodiff, backsolve and finite differences through `value_and_grad`, each `jax.jit`-compiled once."""
    methods = {"autodiff": "autodiff", "backsolve": BACKSOLVE, "fd": fj.FiniteDifferences(step=FD_STEP)}
    return {name: jax.jit(lambda x, m=m: fj.value_and_grad(case, x, m, rtol=RTOL, atol=ATOL))
            for name, m in methods.items()}


@pytest.fixture(scope="module")
def direct_scene_fn(case):
    """The direct method as `value_and_grad_scene`: the gradient with respect to every scene parameter
    (body data, crank radius, law coefficients), compiled once. Its design gradient is the pull-back
    through `p(x)` (`scene_pullback`), exactly what `value_and_grad(case, x, "direct")` computes."""
    return eqx.filter_jit(lambda scene: fj.value_and_grad_scene(case, scene, "direct", rtol=RTOL, atol=ATOL))


@pytest.fixture(scope="module")
def scene_pullback(case):
    return eqx.filter_jit(lambda x, g: eqx.filter_vjp(case.scene, x)[1](g)[0])


@pytest.fixture(scope="module")
def direct_at_x(case, x, direct_scene_fn):
    return direct_scene_fn(case.scene(x))


@pytest.fixture(scope="module")
def gradients(x, adjoint_fn, method_fns, direct_at_x, scene_pullback):
    """`(psi, grad)` at the random design by all five methods."""
    out = {"adjoint": jax.block_until_ready(adjoint_fn(x))}
    for name, fn in method_fns.items():
        out[name] = jax.block_until_ready(fn(x))
    psi, g_scene = direct_at_x
    out["direct"] = (psi, scene_pullback(x, g_scene))
    return {name: (float(psi), np.asarray(g)) for name, (psi, g) in out.items()}


def _central_difference(f, h):
    return (f(h) - f(-h)) / (2 * h)


# --- all five methods agree ----------------------------------------------------------------------
def test_every_method_returns_psi_and_a_gradient_shaped_like_x(case, x, gradients, psi_fn):
    psi_ref = float(psi_fn(x, _radius(case.scene_template)))
    for name, (psi, grad) in gradients.items():
        assert grad.shape == x.shape and grad.dtype == x.dtype, name
        assert np.all(np.isfinite(grad)), f"{name}: non-finite gradient"
        np.testing.assert_allclose(psi, psi_ref, rtol=1e-10, err_msg=f"{name}: psi differs from the forward solve")


def test_adjoint_agrees_with_autodiff(gradients):
    assert_close_relative(gradients["adjoint"][1], gradients["autodiff"][1], ADJOINT_VS_AUTODIFF,
                          "adjoint vs autodiff gradient")


@pytest.mark.parametrize("method", ["backsolve", "direct"])
def test_backsolve_and_direct_agree_with_adjoint_and_autodiff(gradients, method):
    for reference in ("adjoint", "autodiff"):
        assert_close_relative(gradients[method][1], gradients[reference][1], METHODS_AGREE,
                              f"{method} vs {reference} gradient")


def test_central_differences_on_every_entry(gradients):
    fd = gradients["fd"][1]
    assert np.all(np.isfinite(fd)), "every entry is differenced"
    for reference in ("adjoint", "autodiff"):
        assert_close_relative(fd, gradients[reference][1], FINITE_DIFFERENCES,
                              f"central differences (h = {FD_STEP}) vs {reference} gradient")


# --- directional derivatives ---------------------------------------------------------------------
def test_directional_derivative_against_jvp_and_finite_differences(case, x, adjoint_fn, psi_jvp_fn, psi_fn):
    rng = np.random.default_rng(7)
    radius = _radius(case.scene_template)
    _, grad = adjoint_fn(x)
    for _ in range(3):
        v = jnp.asarray(rng.normal(size=case.n_design))
        v = v / jnp.linalg.norm(v)
        along = float(grad @ v)
        tangent = float(psi_jvp_fn(x, radius, v)[1])
        fd = float(_central_difference(lambda h: psi_fn(x + h * v, radius), FD_STEP))
        np.testing.assert_allclose(along, tangent, rtol=1e-6, err_msg="grad . v vs jax.jvp of psi")
        np.testing.assert_allclose(along, fd, rtol=1e-5, err_msg="grad . v vs central differences")


# --- hard case: two retained eigenvalues cross -----------------------------------------------------
def _mode_families(case, x):
    """Eigenvalues of the hinged–hinged problem and whether each mode is axial (symmetric about the
    rod's mid-plane) or bending, from the share of axial displacement in the mode."""
    k, m = (np.asarray(a) for a in case.fe_matrices(jnp.asarray(x)))
    free = np.setdiff1d(np.arange(k.shape[0]), case.fixed_dofs)
    lam, v = scipy.linalg.eigh(k[np.ix_(free, free)], m[np.ix_(free, free)])
    modes = np.zeros((k.shape[0], v.shape[1]))
    modes[free] = v
    axial_share = np.sum(modes[0::2] ** 2, axis=0) / np.sum(modes**2, axis=0)
    return lam, axial_share > 0.5


def crossing_design(case):
    """A design where retained eigenvalues 2 and 3 coincide (the first axial and the second bending
    mode), found by bisection on a one-parameter family of designs.

    Designs with equal element rows are symmetric about the rod's mid-plane, so axial (symmetric)
    and bending (antisymmetric) modes do not interact and their eigenvalues cross exactly instead
    of veering. Family: densities `0.5 + s` on the three design columns next to A, 0.5 elsewhere;
    the axial mode is the third at `s = -0.2` and the second at `s = -0.3`.
    """
    columns = np.arange(case.mesh.nx - 2) < 3

    def design(s):
        return np.tile(np.where(columns, 0.5 + s, 0.5), case.mesh.ny)

    def axial_minus_bending(s):
        lam, axial = _mode_families(case, design(s))
        return lam[:MODES][axial[:MODES]][0] - lam[:MODES][~axial[:MODES]][1]

    lo, hi = -0.3, -0.2
    assert axial_minus_bending(lo) < 0 < axial_minus_bending(hi), "the family brackets a crossing"
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        try:
            below = axial_minus_bending(mid) < 0
        except IndexError:  # modes mixed inside a degenerate pair: the crossing is reached
            break
        lo, hi = (mid, hi) if below else (lo, mid)
    return jnp.asarray(design(0.5 * (lo + hi)))


def test_crossing_eigenvalues_give_a_finite_gradient_matching_finite_differences(case, adjoint_fn, method_fns):
    x = crossing_design(case)
    lam, _ = _mode_families(case, x)
    gap = (lam[2] - lam[1]) / lam[2]
    assert gap < 1e-9, f"retained eigenvalues 2 and 3 coincide (relative gap {gap:.1e})"
    assert (lam[MODES] - lam[MODES - 1]) / lam[MODES] > 0.1, "the discarded modes stay well apart"

    psi, grad = (np.asarray(a) for a in adjoint_fn(x))
    assert np.all(np.isfinite(grad)), "adjoint gradient at the crossing is finite"
    psi_fd, fd = (np.asarray(a) for a in method_fns["fd"](x))
    np.testing.assert_allclose(psi, psi_fd, rtol=1e-10)
    assert_close_relative(grad, fd, FINITE_DIFFERENCES, "adjoint vs central differences at the crossing")
    assert_close_relative(grad, np.asarray(method_fns["autodiff"](x)[1]), ADJOINT_VS_AUTODIFF,
                          "adjoint vs autodiff at the crossing")


# --- usage: jit, vmap, no retracing; a scene parameter ------------------------------------------
@pytest.fixture(scope="module")
def second_design(case, adjoint_fn, gradients):
    """A second random design and its per-design adjoint call (after the first call at `x`)."""
    del gradients  # the first call of adjoint_fn happens there
    x2 = random_design(case, 1)
    return x2, adjoint_fn(x2)


def test_jit_does_not_retrace_for_new_designs(adjoint_traces, second_design):
    del second_design  # the call with a new design
    assert len(adjoint_traces) == 1, f"jit retraced for a new design of the same shape: {adjoint_traces}"


def test_vmap_equals_per_design_calls(case, x, gradients, second_design):
    x2, (psi2, grad2) = second_design
    per_design = [gradients["adjoint"], (float(psi2), np.asarray(grad2))]
    psis, grads = jax.jit(jax.vmap(lambda x: fj.value_and_grad(case, x, ADJOINT, rtol=RTOL, atol=ATOL)))(
        jnp.stack([x, x2]))
    for k, (psi, grad) in enumerate(per_design):
        np.testing.assert_allclose(float(psis[k]), psi, rtol=1e-10, err_msg=f"vmap psi, design {k}")
        assert_close_relative(grads[k], grad, 1e-10, f"vmap gradient vs per-design call, design {k}")


def test_gradient_with_respect_to_the_crank_radius(case, x, direct_at_x, psi_fn):
    """A scene parameter, not a density: `value_and_grad_scene` against central differences."""
    _, g_scene = direct_at_x
    radius = _radius(case.scene_template)
    fd = _central_difference(lambda h: psi_fn(x, radius + h), 1e-6)
    np.testing.assert_allclose(float(_radius(g_scene)), float(fd), rtol=1e-5,
                               err_msg="dpsi/d(crank radius): direct method vs central differences")


# --- bad input -----------------------------------------------------------------------------------
def test_unknown_method_is_a_clear_error(case, x):
    with pytest.raises(ValueError, match=r"Unknown sensitivity method 'adjont'.*choose one of"):
        fj.value_and_grad(case, x, "adjont")
    with pytest.raises(ValueError, match="Unknown sensitivity method"):
        fj.value_and_grad_scene(case, case.scene_template, "bogus")


@pytest.mark.parametrize("shape", [(NY * (NX - 2) - 1,), (NY * (NX - 2) + 2,), (NY, NX - 2)])
def test_design_of_wrong_shape_is_a_clear_error(case, shape):
    # A ValueError from the design map's check; under this suite's jaxtyping hook a 2-D array is already
    # refused by the annotation `Float[Array, "n_design"]` (a TypeError naming `n_design`).
    message = r"Design vector has shape .* expected \(20,\)|n_design"
    with pytest.raises((ValueError, TypeError), match=message):
        fj.value_and_grad(case, jnp.full(shape, 0.5))
    with pytest.raises((ValueError, TypeError), match=message):
        jax.jit(lambda x: fj.value_and_grad(case, x, "autodiff"))(jnp.full(shape, 0.5))


def test_finite_differences_of_scene_parameters_is_a_clear_error(case):
    with pytest.raises(ValueError, match="Finite differences act on the design"):
        fj.value_and_grad_scene(case, case.scene_template, "fd")


# --- the command line ----------------------------------------------------------------------------
def test_cli_gradient_writes_json_and_plot(case, method_fns, tmp_path, capsys):
    """`ffr-jax gradient` on the module's case; `--method fd` keeps the command's own compilation short
    (a forward solve), and the JSON must equal `value_and_grad` with the same method."""
    path, png = tmp_path / "gradient.json", tmp_path / "gradient.png"
    argv = ["gradient", "slider-crank", "--nx", str(NX), "--ny", str(NY), "--modes", str(MODES), "--t1", str(T1),
            "--method", "fd", "--fd-step", str(FD_STEP), "--rtol", str(RTOL), "--atol", str(ATOL),
            "--json", str(path), "--plot", str(png)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    for text in ("psi =", "gradient: min", "sign pattern by element row", "row 1", "timings: compile"):
        assert text in out, f"{text!r} missing from the printed summary"
    record = json.loads(path.read_text())
    assert set(record) >= {"psi", "grad", "timings"}
    assert set(record["timings"]) >= {"compile_s", "compile_and_first_call_s", "second_call_s"}
    psi, grad = method_fns["fd"](case.initial_design(0.5))
    np.testing.assert_allclose(record["psi"], float(psi), rtol=1e-10, err_msg="CLI psi vs value_and_grad")
    assert_close_relative(np.asarray(record["grad"]), grad, 1e-8, "CLI gradient vs value_and_grad")
    assert png.stat().st_size > 10_000, "the gradient picture is written"


def test_cli_rejects_an_unknown_method(capsys):
    with pytest.raises(SystemExit):
        main(["gradient", "slider-crank", "--method", "adjont"])
    assert "invalid choice: 'adjont'" in capsys.readouterr().err
