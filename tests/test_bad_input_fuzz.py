"""Issue 17: every bad input in `bad_input_cases` (API and CLI) gives the package's clear error.

Each row of `bad_input_cases.API` is one call that must raise its error class with a message that
matches (the message comes first: no XLA or equinox wrapper text in front of it, and no library
traceback); each row of `bad_input_cases.CLI` is one `ffr-jax` command line that must exit with
status 2 and print one line `ffr-jax: error: ...`. The CLI rows run `ffr_jax._app._cli.main` in this
process (a subprocess per row would cost a JAX import each); one subprocess checks the real entry
point. All rows share one small case and its compiled forward solve (see `bad_input_cases`).

Below the table: what the issue asked to *work* rather than fail (finite differences at the bounds,
float32 designs give float64 gradients, strict JSON, a user's `jax.jit` error message first).
"""

import logging
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from bad_input_cases import API, CLI, SLOW_32, Ctx, non_grashof_four_bar, run_cli, strict_json_of, user_view

import ffr_jax as fj

ROOT = Path(__file__).resolve().parent.parent
# A message that carries a library's traceback or XLA's wrapper is what the issue is about.
FOREIGN = ("Traceback", "INTERNAL:", "CpuCallback", "EquinoxRuntimeError", "jaxlib", "scipy")


@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    return Ctx(tmp_path_factory.mktemp("bad_input"))


@pytest.mark.parametrize("bad", API, ids=[b.name for b in API])
def test_api_bad_input(ctx, bad):
    with user_view(), pytest.raises(bad.error, match=bad.match) as info:
        jax.block_until_ready(bad.call(ctx))
    message = str(info.value)
    assert not any(word in message for word in FOREIGN), f"foreign text in the message: {message[:300]}"


@pytest.mark.slow
@pytest.mark.parametrize("bad", SLOW_32, ids=[b.name for b in SLOW_32])
def test_api_bad_input_compiling_its_own_program(ctx, bad):
    """The rows that compile a program of their own (a user's integrand, another scene): 5-40 s each."""
    test_api_bad_input(ctx, bad)


@pytest.mark.slow
def test_cli_long_horizon_ends_with_the_step_budget(ctx):
    """Issue 32: `ffr-jax gradient ... --t1 1000` (no result in 1,500 s before) ends with the API's error once the
    step budget is used up: exit status 2 and one line. A budget of 2,000 steps (`--max-steps`, the API's
    `max_steps`) for the test; the default 200,000 behaves alike (benchmarks/RESULTS.md, "Bad input (issue 32)")."""
    from bad_input_cases import BadCli

    bad = BadCli("t1 = 1000", "gradient slider-crank --nx 4 --ny 2 --modes 2 --t1 1000 --max-steps 2000",
                 "^ffr-jax: error: The maximum number of solver steps was reached", "CLI (compiled)")
    status, out, err = run_cli(ctx, bad)
    assert status == 2, (status, out[-300:], err[-300:])
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ffr-jax: error: The maximum number of solver steps was reached"), err
    assert not any(word in err for word in FOREIGN), err


@pytest.mark.parametrize("bad", CLI, ids=[b.name for b in CLI])
def test_cli_bad_input(ctx, bad):
    status, out, err = run_cli(ctx, bad)
    assert status == 2, f"exit status {status}; stdout {out[-300:]!r}; stderr {err[-300:]!r}"
    lines = err.strip().splitlines()
    assert lines and lines[-1].startswith(("ffr-jax: error: ", "ffr-jax optimize: error: ", "ffr-jax gradient: error: ")), err
    assert len(lines) <= 3 and not any(word in err for word in FOREIGN), err  # argparse adds a usage line
    import re

    assert re.search(bad.match, lines[-1]), f"{lines[-1]!r} does not match {bad.match!r}"
    # Refused before any computation: nothing was printed about a run.
    assert "compile" not in out and "wrote" not in out, out


def test_cli_entry_point_in_a_subprocess(tmp_path):
    """The installed entry point (`ffr_jax._app._cli:main`): status 2, one line on stderr, before any compilation."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    result = subprocess.run(
        [sys.executable, "-c", "import sys; from ffr_jax._app._cli import main; sys.exit(main())",
         "gradient", "slider-crank", "--json", str(tmp_path / "missing" / "psi.json")],
        capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"ffr-jax: error: --json {tmp_path / 'missing' / 'psi.json'}: the directory {tmp_path / 'missing'} does not "
        "exist; create it first or choose another path."]


def test_every_issue_item_has_a_row():
    """The items of issue 17, each named by a row of the table (a row removed by mistake fails here)."""
    names = {b.name for b in API} | {b.name for b in CLI}
    items = ["t1 = nan", "--t1 nan", "objective rtol = 1", "--rtol -1", "Backsolve(rtol=-1)", "objective rtol = 0",
             "objective atol = -1e-12", "Adjoint(atol=-1)", "FiniteDifferences(step=0)",
             "FiniteDifferences(entries=(99,))", "FiniteDifferences(step=-1e-5)", "FiniteDifferences(batch_size=0)",
             "DensityFilter(radius=inf)", "SIMP(x_min=0)", "SIMP(stiffness_penalty=-3)", "SIMP(mass_factor=-1e5)",
             "SIMP(x_switch=1.5)", "SIMP(density=-8750)", "complex design", "density 1.5 under jax.vmap",
             "NaN density under jax.vmap", "inf density under jax.vmap", "density 1.5 under jax.jit + clean_errors",
             "max_steps = 0", "max_steps = -1", "n_modes = 3.0", "objective rtol = nan",
             "dead point, eccentricity 0.99999 l", "checkpoint with NaN design", "checkpoint with density 1.5",
             "--resume a checkpoint with NaN design", "--resume a checkpoint with inf optimizer state",
             "--json to a missing directory", "--json to a directory", "--plot to a missing directory",
             "--plot to a directory"]
    assert not set(items) - names, set(items) - names


def test_every_issue_32_item_has_a_row():
    """The rows of issue 32 that this table checks (the run folder and CLI stop messages are in
    tests/test_run_folder.py; NumPy integers below)."""
    names = {b.name for b in API} | {b.name for b in CLI}
    items = ["Revolute(marker_j=7) on a body with 2 markers", "GroundRevolute(body=-1)", "SpringDamper on marker 9",
             "MarkerTracking(body=0, marker=9)", "Revolute to body 2 of 2", "detached piece: fj.objective(case, x)",
             "detached piece: uniform_body_data()", "negative modal stiffness (eqx.tree_at) -> Problem()",
             "HeavisideProjection beta = inf", "fj.optimize(beta=inf)", "FiniteDifferences(step=1e-12) at rtol 1e-10",
             "--resume a slider-crank run as link-four-bar", "optimize --mass-max nan", "optimize --out ''",
             "SpringDamper(stiffness=nan)", "Gravity((0, nan))", "ConstantSpeedLaw(nan)",
             "FunctionConstraint with a NaN bound", "MMA with x0 of the wrong length",
             "x64 turned off after import: fj.value_and_grad", "--json where no file can be created (/sys)",
             "integrand turning NaN midway: fj.objective", "non-Grashof four-bar driven past its limit angle",
             "t1 = 1000 through the cached gradient: fj.value_and_grad(max_steps=2000)", "gradient --max-steps 0"]
    assert not set(items) - names - {b.name for b in SLOW_32}, set(items) - names - {b.name for b in SLOW_32}


# --- what must work -------------------------------------------------------------------------------

def test_user_jit_error_reads_the_package_message_first(ctx, caplog):
    """Under a user's own `jax.jit` the exception is XLA's (nothing of the package runs when the program
    executes), but jax's log record of the failed callback, printed first, is one line: the message.
    (`ctx.jitted` is the jitted modal solve; the design check that fails is the same in every program.)"""
    with caplog.at_level(logging.ERROR, logger="jax._src.callback"):
        with pytest.raises(jax.errors.JaxRuntimeError) as info:
            jax.block_until_ready(ctx.jitted(ctx.x.at[2].set(-0.5)))
    assert "Design densities must lie in [x_min, 1]" in str(info.value)
    records = [r.getMessage() for r in caplog.records if r.name == "jax._src.callback"]
    assert records and records[0].startswith("ffr_jax: Design densities must lie in [x_min, 1]"), records
    assert "\n" not in records[0]


def test_finite_differences_at_the_bounds_and_float32(ctx):
    """Densities at 1 and at x_min are differenced one-sided (before: a bounds error naming no step); the
    quotient is the one-sided one of two objective values. A float32 design gives a float64 gradient."""
    h = ctx.FD.step
    x = ctx.x.at[0].set(1.0).at[1].set(ctx.case.material.x_min)
    psi, grad = ctx.gradient(ctx.case, x)
    grad = np.asarray(grad)
    assert grad.dtype == np.float64 and np.all(np.isfinite(grad[:3])) and np.all(np.isnan(grad[3:]))
    # psi at x - h e_0 and at x + h e_1: the value that the same program returns at those designs.
    psi_down = float(ctx.gradient(ctx.case, x.at[0].add(-h))[0])
    psi_up = float(ctx.gradient(ctx.case, x.at[1].add(h))[0])
    down, up = (float(psi) - psi_down) / h, (psi_up - float(psi)) / h
    # The same forward solves (rtol 1e-10) at the same designs, in other lanes of the batch: their values
    # agree to a few rtol of psi, so the quotients to ~1e-10 psi / h = 1e-6 psi; 1e-4 of the entry's
    # size leaves room and still tells the one-sided quotient from any other (a central one would
    # evaluate outside [x_min, 1] and raise).
    for fd_value, quotient in ((grad[0], down), (grad[1], up)):
        assert abs(fd_value - quotient) <= 1e-4 * abs(quotient) + 1e-6 * abs(float(psi)), (fd_value, quotient)
    _, grad32 = ctx.gradient(ctx.case, ctx.x.astype(jnp.float32))
    assert grad32.dtype == jnp.float64


def test_cli_json_is_strict():
    """The CLI writes strict JSON: a NaN or inf is refused with the key's name, never written as bare `NaN`."""
    assert strict_json_of({"psi": 1.0, "grad": [0.5, 2.0]}) == '{"psi": 1.0, "grad": [0.5, 2.0]}'
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match=r"--json out.json: grad\[1\] is .*; nothing was written"):
            strict_json_of({"psi": 1.0, "grad": [0.5, bad]})


def test_numpy_integers_are_integers():
    """Issue 32: `slider_crank(nx=np.int64(4))` ("nx must be at least 4 ... got 4" before) builds the same case as
    Python ints: the same static sizes (Python ints, so the compiled programs are shared) and the same design."""
    with user_view():  # the suite's runtime type checks read the annotation `int` strictly
        case = fj.cases.slider_crank(np.int64(4), np.int64(2), np.int64(2), 0.1, t_ramp=0.05)
    assert (case.mesh.nx, case.mesh.ny, case.n_modes) == (4, 2, 2)
    assert all(type(n) is int for n in (case.mesh.nx, case.mesh.ny, case.n_modes))
    assert case.n_design == 4


def test_committed_design_is_not_recompiled(ctx, caplog):
    """Issue 32: a design committed to the default device (`jax.device_put(x, device)`) runs the program compiled
    for the plain design (before: its sharding entered the compile cache's key, and the reference gradient compiled
    again for 57 s). Counted from JAX's own compile log; the forward solve of the small case is compiled in this
    module already (the dead-point rows), or here first."""
    psi = fj.objective(ctx.case, ctx.x)
    committed = jax.device_put(ctx.x, jax.devices()[0])
    assert committed.committed
    with jax.log_compiles(True), caplog.at_level(logging.DEBUG):
        psi_committed = fj.objective(ctx.case, committed)
    # The forward program (`Program(_simulate_case_fn)` in ffr_jax/_api.py) must not compile again; converting the
    # design to float64 may compile a one-operation program for the new argument (milliseconds).
    compiles = [r.getMessage()[:80] for r in caplog.records if r.getMessage().startswith("Compiling ")]
    assert not any("_simulate_case_fn" in m for m in compiles), compiles
    assert float(psi_committed) == float(psi)  # the same program on the same numbers


def test_output_not_written_after_computing_is_one_line(tmp_path):
    """Issue 32: a file the CLI cannot write after computing (the options were checked before; the directory went
    away or turned read-only since) is one `ValueError` line that says nothing was saved, not an OSError traceback."""
    from ffr_jax._app._cli_checks import written

    gone = tmp_path / "gone" / "psi.json"  # a real OSError (FileNotFoundError) at the write
    with pytest.raises(ValueError, match=r"^--json .*psi.json: could not write the file \(No such file or directory\); "
                                         "the results printed above were computed but not saved"):
        written(lambda path: path.write_text("{}"), gone, "--json")


@pytest.mark.slow
def test_non_grashof_four_bar_before_its_limit_angle_runs():
    """Issue 32: a four-bar that is no Grashof linkage, run up to t1 = 0.5 s (crank angle 1.57 rad, its limit angle
    2.31 rad), runs with diffrax's first step (the issue saw Newton's error there; it ran with dt0 = 1e-4), and gives
    the psi of dt0 = 1e-4: the two solves differ in their step sequences only, each within rtol = 1e-10 of the exact
    psi per unit time over 0.5 s of a smooth motion, so 1e-6 of psi bounds their difference with room for the error's
    growth. (Driven past the limit angle it is a dead point: the row in SLOW_32.)"""
    with user_view():
        default = non_grashof_four_bar(0.5)
        x = default.initial_design(0.5)
        psi = float(fj.objective(default, x))
        psi_small_step = float(fj.objective(non_grashof_four_bar(0.5, dt0=1e-4), x))
    assert np.isfinite(psi) and psi > 0
    assert abs(psi - psi_small_step) <= 1e-6 * abs(psi_small_step), (psi, psi_small_step)
