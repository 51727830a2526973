"""The optimisation loop, filter, volume, checkpoints and CLI on the two-link design (issue 14).

The loop itself on a dict design (MMA, a filter per body, a shared volume or one per body) is issue 16's
(tests/test_optimize.py); here: the CLI scene `four-bar-two-links`, its bad options, and the stacked design
with Adam (test_design_stacked.py has the stacked filter and volume).
"""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from ffr_jax._app._cli import main


@pytest.mark.parametrize("argv, message", [
    (["--volume-per-body", "0.4"], r"one fraction per designed rod \['coupler', 'rocker'\]"),
    (["--optimizer", "adam"], r"does not take --optimizer adam \(a dict design needs mma\)"),
    (["--frequency-min", "50"], r"does not take --frequency-min"),
])
def test_cli_two_links_refuses_what_it_cannot_do(tmp_path, capsys, argv, message):
    code = main(["--no-cache", "optimize", "four-bar-two-links", "--nx", "8", "--ny", "2", "--modes", "1", "--t1",
                 "0.1", "--iters", "1", "--no-progress", "--out", str(tmp_path / "run"), *argv])
    assert code == 2 and re.search(message, capsys.readouterr().err)


def test_cli_volume_per_body_needs_several_bodies(tmp_path, capsys):
    code = main(["--no-cache", "optimize", "slider-crank", "--nx", "8", "--ny", "2", "--modes", "1", "--t1", "0.1",
                 "--iters", "1", "--volume-per-body", "0.4", "0.5", "--no-progress", "--out", str(tmp_path / "run")])
    assert code == 2 and "--volume-per-body is for a scene with several designed bodies" in capsys.readouterr().err


@pytest.mark.slow  # an adjoint compile of its own (minutes); bench_two_links_optimize.py runs the worked example
def test_cli_optimizes_both_links_with_a_volume_per_body_and_resumes(tmp_path):
    """Two steps, then resumed to three: the log, checkpoint and the per-rod designs and picture are written;
    MMA keeps each rod's volume at or below its bound (its constraint is an inequality; 1e-6 slack for
    the subproblem's own tolerance). The two runs share a fresh cache folder, as a user's runs share theirs:
    the resumed run loads the gradient the first one compiled (110 s in CI's slow set when both compiled)."""
    env = {k: v for k, v in os.environ.items() if k not in ("FFR_JAX_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env.update(PYTHONPATH=os.getcwd(), FFR_JAX_CACHE_DIR=str(tmp_path / "cache"))
    out = tmp_path / "run"
    cli = [sys.executable, "-m", "ffr_jax", "optimize", "four-bar-two-links"]
    base = ["--nx", "8", "--ny", "2", "--modes", "2", "--t1", "0.3", "--atol", "1e-14", "--volume-per-body", "0.4",
            "0.6", "--no-progress", "--checkpoint-every", "2"]
    run = subprocess.run(cli + base + ["--iters", "2", "--out", str(out)], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    run = subprocess.run(cli + ["--iters", "3", "--resume", str(out), "--no-progress"], env=env, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    saved = np.load(out / "design.npz")
    assert json.loads(str(saved["config"]))["volume_per_body"] == [0.4, 0.6] and len(saved["psi"]) == 3
    for name, v in (("coupler", 0.4), ("rocker", 0.6)):
        assert np.mean(saved[f"x_phys_{name}"]) <= v + 1e-6, name
    assert (out / "design.png").stat().st_size > 0 and (out / "log.csv").exists()
