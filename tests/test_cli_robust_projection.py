"""`ffr-jax optimize --eta-eroded/--eta-dilated/--robust-objective` (issue 30): the robust formulation of the
projection from the shell, refused with `fj.HeavisideProjection`'s own rule, and run as the Python API runs it."""

import json

import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._app._cli import main

# test_optimize.py's tiny CLI case and tolerances, with MMA (which projects by default).
TINY = ["slider-crank", "--nx", "8", "--ny", "2", "--modes", "2", "--t1", "0.2", "--rtol", "1e-6", "--atol", "1e-12",
        "--method", "adjoint", "--optimizer", "mma", "--no-progress"]


@pytest.mark.parametrize("options, match", [
    (["--eta-eroded", "0.4", "--eta-dilated", "0.3"], "0 < eta_dilated < eta < eta_eroded < 1"),
    (["--eta-eroded", "0.7", "--eta-dilated", "0.6"], "0 < eta_dilated < eta < eta_eroded < 1"),
    (["--eta-eroded", "1", "--eta-dilated", "0.3"], "0 < eta_dilated < eta < eta_eroded < 1"),
    (["--eta-eroded", "0.7"], "both thresholds"),
    (["--eta-dilated", "0.3"], "both thresholds"),
    (["--robust-objective", "eroded"], "needs the robust formulation"),
    (["--eta-eroded", "nan", "--eta-dilated", "0.3"], "--eta-eroded must be finite"),
])
def test_bad_robust_thresholds_are_refused_with_the_api_rule(tmp_path, capsys, options, match):
    # The same thresholds the Python API refuses (tests/test_robust_projection.py), refused before anything is built.
    assert main(["optimize", *TINY, *options, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert match in err and options[0] in err, err
    assert not (tmp_path / "run").exists(), "a refused run writes nothing"


def test_the_robust_projection_needs_a_projection(tmp_path, capsys):
    options = ["--eta-eroded", "0.7", "--eta-dilated", "0.3", "--out", str(tmp_path / "run")]
    assert main(["optimize", *TINY[:-3], "--optimizer", "adam", *options]) == 2  # adam does not project by default
    assert "is a form of the projection" in capsys.readouterr().err
    assert main(["optimize", "four-bar-two-links", *options]) == 2
    assert "four-bar-two-links does not take --eta-eroded, --eta-dilated" in capsys.readouterr().err


@pytest.mark.slow  # the case build and the MMA step's compile cost more than the default suite allows
def test_cli_robust_run_optimises_the_named_design_and_reports_the_blueprint(tmp_path, capsys):
    from ffr_jax._app._cli_optimize import _problem

    # The objective on the eroded design (one solve per step: the min-max's three cost three times the compile;
    # the options reach fj.HeavisideProjection the same way for every --robust-objective).
    assert main(["optimize", *TINY, "--eta-eroded", "0.7", "--eta-dilated", "0.3", "--robust-objective", "eroded",
                 "--iters", "2", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "robust: eroded / blueprint / dilated at eta 0.7 / 0.5 / 0.3, objective eroded" in out, out
    stored = fj.load_checkpoint(tmp_path / "checkpoint.npz").config
    assert (stored["eta_eroded"], stored["eta_dilated"], stored["robust_objective"]) == (0.7, 0.3, "eroded"), stored
    # The run's objective is the one the Python API builds from these options: the CLI's cached problem, called
    # again (no new compile), gives the logged psi of step 0 (the same function of the same input; were it compiled
    # apart, round-off steered through an adaptive solve at rtol 1e-6 bounds the gap by about 1e-6).
    geometry = (("modes", 2), ("nx", 8), ("ny", 2), ("t1", 0.2))
    case, filt, projection, fun = _problem("slider-crank", geometry, 1.5, 0.5, "adjoint", 1e-6, 1e-12, None,
                                           (0.7, 0.3, "eroded"))
    assert projection == fj.HeavisideProjection(0.5, x_min=case.material.x_min, eta_eroded=0.7, eta_dilated=0.3,
                                                objective="eroded")
    x0 = case.initial_design(0.5)
    psi0 = float(fun(x0, 1.0)[0])
    log = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(log[0, 1], psi0, rtol=1e-6)
    # A run that ignored the options would have logged psi of the blueprint, whose uniform density at beta = 1 lies
    # above the eroded design's (P_1 of u = 0.495 at eta 0.5 and 0.7, by hand: 0.495 and 0.449); psi (mass and
    # stiffness both scale with the density) then differs by far more than the 1e-6 above.
    eroded, blueprint, _ = (np.asarray(d) for d in projection.designs(filt(x0), 1.0))
    assert np.all(blueprint - eroded > 0.02), (blueprint, eroded)
    # The reported design is the blueprint: design.npz's x_phys is fj.physical_densities at the last beta.
    saved = np.load(tmp_path / "design.npz")
    expected = fj.physical_densities(saved["x"], filt, projection, float(saved["beta"]))
    np.testing.assert_allclose(saved["x_phys"], np.asarray(expected), rtol=0, atol=1e-14)
    assert json.loads(str(saved["config"]))["robust_objective"] == "eroded"
