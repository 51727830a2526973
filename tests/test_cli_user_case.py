"""The commands on a user's case: `ffr-jax info|gradient|optimize|animate|export my_case.py:make_case`, a
Python file in tmp_path whose function returns a case (run in-process through `ffr_jax._app._cli.main`).

The case and the solver settings are those of tests/test_io.py's tiny run (8 x 2 rod, 2 modes, t1 = 0.2 s,
adjoint at rtol 1e-6, atol 1e-12, the default filter), so that the programs compile once for both (in one
process, or through the persistent compilation cache).
"""

import json

import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._app._cli import main

USER_CASE = '''
import ffr_jax as fj


def make_case():
    return fj.cases.slider_crank(nx=8, ny=2, n_modes=2, t1=0.2)


def not_a_case():
    return 42
'''


@pytest.fixture(scope="module")
def user_case(tmp_path_factory):
    path = tmp_path_factory.mktemp("user") / "my_case.py"
    path.write_text(USER_CASE)
    return f"{path}:make_case"


@pytest.fixture(scope="module")
def optimized(user_case, tmp_path_factory):
    directory = tmp_path_factory.mktemp("run") / "run"
    assert main(["optimize", user_case, "--iters", "2", "--rtol", "1e-6", "--atol", "1e-12", "--method", "adjoint",
                 "--no-progress", "--out", str(directory)]) == 0
    return directory


def test_info_and_gradient_of_a_user_case(user_case, tmp_path, capsys):
    assert main(["info", user_case]) == 0
    out = capsys.readouterr().out
    assert "my_case.py:make_case: body 'rod'" in out and "natural frequencies" in out
    record_path, plot = tmp_path / "g.json", tmp_path / "g.png"
    # Finite differences: the forward solve alone compiles (the adjoint's program is tests/test_sensitivity's).
    assert main(["gradient", user_case, "--method", "fd", "--fd-step", "1e-3", "--rtol", "1e-6", "--atol", "1e-12",
                 "--json", str(record_path), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    record = json.loads(record_path.read_text())
    case = fj.cases.slider_crank(nx=8, ny=2, n_modes=2, t1=0.2)
    assert len(record["grad"]) == case.n_design and plot.stat().st_size > 10_000
    # One solve: the compiled gradient is called once, and the summary says what its time includes.
    assert record["timings"]["calls"] == 1 and record["timings"]["second_call_s"] is None
    assert "first call" in out and "--repeat" in out


def test_optimize_animate_and_export_a_user_case(user_case, optimized, tmp_path, capsys):
    saved = np.load(optimized / "design.npz")
    assert json.loads(str(saved["config"]))["optimizer"] == "mma" and saved["psi"].shape == (2,)
    design = str(optimized / "design.npz")
    assert main(["animate", user_case, "--design", design, "--out", str(tmp_path / "a.gif"), "--frames", "4"]) == 0
    pvd, svg = tmp_path / "motion.pvd", tmp_path / "design.svg"
    assert main(["export", user_case, "--design", design, "--vtu-series", str(pvd), "--frames", "4",
                 "--svg", str(svg)]) == 0
    out = capsys.readouterr().out
    assert "4 frames" in out and f"wrote {pvd}" in out and svg.is_file()
    assert len(list((tmp_path / "motion_vtu").glob("*.vtu"))) == 4


def test_bad_user_cases_are_refused(user_case, tmp_path, capsys):
    function_path = user_case.rpartition(":")[0]
    assert main(["info", f"{function_path}:not_a_case"]) == 2
    assert "not an ffr_jax.Case" in capsys.readouterr().err
    assert main(["info", f"{function_path}:missing"]) == 2
    assert "defines no function 'missing'" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "absent.py:make_case")]) == 2
    assert "No user case file" in capsys.readouterr().err
    assert main(["info", user_case, "--nx", "8"]) == 2
    assert "--nx: not an option" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["info", "slider-crunk"])
    assert exit_.value.code == 2 and "FILE.py:FUNCTION" in capsys.readouterr().err
