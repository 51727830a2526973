"""Issue 32: a run directory belongs to one run.

- Ownership: two processes started on one run folder (before: both "owned" it in 3 of 8 trials, and
  one run's checkpoints overwrote the other's): exactly one runs, the other is refused at once.
- Resume: a checkpoint of another objective (case, mesh), other constraints or other optimizer
  settings is refused unless asked to override (`force_resume`); the CLI refuses a checkpoint of
  another scene.
- The CLI reports a file-system error or Ctrl-C in one line with the checkpoint it kept and the
  command that continues the run.

Every run here is on a quadratic surrogate of four densities (no simulation, nothing to compile
beyond a few small programs), except the CLI tests, which build the small slider-crank case.
"""

import contextlib
import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ffr_jax as fj
from ffr_jax._app._checkpoint import Checkpoint, save_checkpoint
from ffr_jax._app._run_lock import RunLock

ROOT = Path(__file__).resolve().parent.parent
X0 = jnp.full(4, 0.5)


def _quadratic(target=0.3):
    return jax.value_and_grad(lambda x: jnp.sum((x - target) ** 2))


def _run(directory, iterations, *, fun=None, volume=0.5, move=0.2, **kwargs):
    return fj.optimize(_quadratic() if fun is None else fun, X0, fj.MMA(0.01, move=move), fj.VolumeConstraint(volume),
                       iterations=iterations, directory=directory, progress=False, checkpoint_every=1, **kwargs)


# --- ownership ------------------------------------------------------------------------------------
RACER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import jax, jax.numpy as jnp
    import ffr_jax as fj

    directory, me, other = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
    fun = jax.value_and_grad(lambda x: jnp.sum((x - 0.3) ** 2))
    me.touch()
    while not other.exists():  # both processes imported jax: start together
        time.sleep(0.005)
    try:
        # 0.3 s per step: the winner holds the folder for more than a second after the start.
        fj.optimize(fun, jnp.full(4, 0.5), fj.MMA(0.01), fj.VolumeConstraint(0.5), iterations=4,
                    directory=directory, progress=False, checkpoint_every=1, callback=lambda *a: time.sleep(0.3))
    except fj.CheckpointError as err:
        print(f"REFUSED {err}")
        sys.exit(3)
    print("WON")
""")


def test_two_processes_racing_for_one_run_folder(tmp_path):
    """Exactly one of two processes started together on one folder runs; the other gets a CheckpointError that
    says the folder is in use (or, had it come after the first had finished, that it already holds a run)."""
    script = tmp_path / "racer.py"
    script.write_text(RACER)
    run_dir, a, b = tmp_path / "run", tmp_path / "ready_a", tmp_path / "ready_b"
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    procs = [subprocess.Popen([sys.executable, str(script), str(run_dir), str(me), str(other)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env) for me, other in ((a, b), (b, a))]
    results = [(p.wait(timeout=300), p.stdout.read(), p.stderr.read()) for p in procs]
    codes = sorted(code for code, _, _ in results)
    assert codes == [0, 3], results
    loser = next(out for code, out, _ in results if code == 3)
    assert "is in use by another run" in loser or "already holds a run" in loser, loser
    # The winner's run is whole: 4 steps in its checkpoint and log.
    assert fj.load_checkpoint(run_dir / "checkpoint.npz").iteration == 4
    assert len((run_dir / "log.csv").read_text().splitlines()) == 5


def test_a_held_folder_is_refused_in_process_and_free_after(tmp_path):
    """The lock is the open file's: while held, a run in the folder is refused; once released (the run ended, or
    its process died), the folder is free again."""
    lock = RunLock(tmp_path).acquire()
    try:
        with pytest.raises(fj.CheckpointError, match="is in use by another run"):
            _run(tmp_path, 1)
        assert not (tmp_path / "checkpoint.npz").exists()
    finally:
        lock.release()
    _run(tmp_path, 1)
    _run(tmp_path, 2, resume=True)  # the first run released the folder when it returned
    assert fj.load_checkpoint(tmp_path / "checkpoint.npz").iteration == 2


# --- resume ---------------------------------------------------------------------------------------
def _with_fingerprint(fun, fingerprint):
    def wrapped(x):
        return fun(x)

    wrapped.fingerprint = fingerprint
    return wrapped


def test_resume_refuses_another_objective_constraint_or_optimizer(tmp_path):
    fun = _with_fingerprint(_quadratic(), "case A")
    _run(tmp_path, 1, fun=fun)
    with pytest.raises(fj.CheckpointError, match=r"another constraints \(bounds"):
        _run(tmp_path, 2, fun=fun, volume=0.3, resume=True)
    with pytest.raises(fj.CheckpointError, match="another optimizer settings"):
        _run(tmp_path, 2, fun=fun, move=0.3, resume=True)
    with pytest.raises(fj.CheckpointError, match=r"another objective \(case, mesh"):
        _run(tmp_path, 2, fun=_with_fingerprint(_quadratic(), "case B"), resume=True)
    assert fj.load_checkpoint(tmp_path / "checkpoint.npz").iteration == 1  # nothing was continued
    result = _run(tmp_path, 2, fun=fun, volume=0.3, resume=True, force_resume=True)
    assert result.history.steps == 2
    _run(tmp_path, 3, fun=fun, volume=0.3, resume=True)  # the forced run stored its own fingerprints


def test_changed_settings_are_refused_unless_forced_and_then_named(tmp_path):
    """The `config` settings of a run (the CLI's options) likewise: another value is refused with both values
    named and the way to override; with `force_resume` the run continues, warns which settings changed, and its
    checkpoints keep the new ones (a plain resume with them is accepted after)."""
    _run(tmp_path, 1, config={"beta_max": 64})
    with pytest.raises(fj.CheckpointError, match=r"beta_max: checkpoint 64, now 128.*force_resume=True"):
        _run(tmp_path, 2, config={"beta_max": 128}, resume=True)
    with pytest.warns(UserWarning, match=r"changed settings \(force_resume\): beta_max: checkpoint 64, now 128"):
        result = _run(tmp_path, 2, config={"beta_max": 128}, resume=True, force_resume=True)
    assert result.history.steps == 2
    assert fj.load_checkpoint(tmp_path / "checkpoint.npz").config == {"beta_max": 128}
    _run(tmp_path, 3, config={"beta_max": 128}, resume=True)


def test_make_objective_fingerprints_tell_meshes_apart():
    """Two rods with the same number of densities on other meshes (length 1 and 1.1 m) have other fingerprints; the
    same case built twice has the same (so a resume in a new process is accepted)."""
    a = fj.cases.slider_crank(4, 2, 2, 0.1)
    fingerprint = fj.make_objective(a).fingerprint
    assert fj.make_objective(fj.cases.slider_crank(4, 2, 2, 0.1)).fingerprint == fingerprint
    assert fj.make_objective(fj.cases.slider_crank(4, 2, 2, 0.1, length=1.1)).fingerprint != fingerprint
    assert fj.make_objective(a, rtol=1e-6).fingerprint != fingerprint


# --- the CLI: file-system errors and Ctrl-C -------------------------------------------------------
SMALL = "optimize slider-crank --nx 4 --ny 2 --modes 2 --t1 0.05 --iters 3 --no-progress --out {out}"


def _cli(argv: str, **paths):
    from ffr_jax._app._cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(argv.format(**paths).split())
    return status, out.getvalue(), err.getvalue()


@pytest.mark.parametrize("fault", ["disk full", "Ctrl-C"])
def test_cli_reports_a_stopped_run_in_one_line(tmp_path, monkeypatch, fault):
    """The run stops after its first checkpoint (a fault injected into the driver): one line on stderr with the
    cause, the checkpoint kept and the command that continues the run; no traceback."""
    import ffr_jax._app._cli_optimize as cli

    def optimize(fun, x0, optimizer, constraints, *, directory, config, **kwargs):
        Path(directory).mkdir(parents=True, exist_ok=True)
        x = np.full(4, 0.5)
        history = fj.History(np.ones(1), np.full(1, 0.5), np.full(1, 0.01))
        save_checkpoint(Path(directory) / "checkpoint.npz", Checkpoint(1, x, (), history, config))
        if fault == "Ctrl-C":
            raise KeyboardInterrupt
        raise OSError(28, "No space left on device", str(Path(directory) / "log.csv"))

    monkeypatch.setattr(cli, "optimize", optimize)
    status, _, err = _cli(SMALL, out=tmp_path / "run")
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    cause = "interrupted (Ctrl-C)" if fault == "Ctrl-C" else "No space left on device"
    assert lines[0].startswith("ffr-jax: error: optimize ") and cause in lines[0], lines[0]
    assert f"the last checkpoint (step 1) is kept in {tmp_path / 'run' / 'checkpoint.npz'}" in lines[0], lines[0]
    assert lines[0].endswith(f"continue with ffr-jax optimize slider-crank --resume {tmp_path / 'run'}"), lines[0]
