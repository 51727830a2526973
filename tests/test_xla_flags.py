"""The guard against a deadlock of jaxlib's CPU runtime (ffr_jax/_dynamics/_xla_flags.py): set by the
`ffr-jax` command before JAX starts, warned about by `sharded_map(batch_size=...)`, never by `import ffr_jax`;
the package's kept programs carry it as a compile option (`program_options`, no environment edit).

Batched LAPACK kernels under `jax.vmap`, two independent ones per program (a difference quotient
`f(x + h) - f(x - h)` of a dense modal analysis), hung 3 of 3 runs on 2 cores without the guard; run
here in a fresh process (the suite's own XLA_FLAGS removed) with a time limit, so that a hang fails
the test instead of stalling the suite.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ffr_jax._dynamics._xla_flags import FUSION_OPTION, SCHEDULER_OPTION, program_options

ROOT = Path(__file__).resolve().parents[1]

PROGRAM = """
from ffr_jax._dynamics._xla_flags import avoid_batched_lapack_deadlock
avoid_batched_lapack_deadlock()  # what the ffr-jax command does first
import ffr_jax, jax, jax.numpy as jnp, os
assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in os.environ["XLA_FLAGS"], os.environ["XLA_FLAGS"]
def f(s):
    a = jnp.eye(80) * (2.0 + s) + 0.1
    return jnp.linalg.cholesky(a).sum()
g = jax.jit(jax.vmap(lambda s: f(s) - f(-s)))
x = jnp.linspace(0.0, 0.5, 48)
for k in range(200):
    g(x + k).block_until_ready()
print("done")
"""


def _run(program: str, xla_flags: str | None, timeout: float):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", program], env=env, capture_output=True, text=True, timeout=timeout)


def test_batched_lapack_kernels_under_vmap_do_not_deadlock():
    # Unguarded, the program hangs at 0 % CPU within its first calls; guarded it takes a few seconds
    # after import. 120 s is far above that, even on a loaded machine.
    try:
        result = _run(PROGRAM, None, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("batched Cholesky factors under vmap hung: the XLA scheduler flag of ffr_jax/_xla_flags.py is not in effect")
    assert result.returncode == 0 and "done" in result.stdout, result.stderr[-2000:]


def test_importing_the_package_leaves_the_environment_alone():
    result = _run("import os; before = dict(os.environ); import ffr_jax; print(before == dict(os.environ))", None,
                  timeout=120)
    assert result.returncode == 0 and result.stdout.split() == ["True"], result.stderr[-2000:]


def test_a_setting_of_the_user_is_kept():
    program = ("from ffr_jax._dynamics._xla_flags import avoid_batched_lapack_deadlock as a; a(); "
               "import os; print(os.environ['XLA_FLAGS'])")
    result = _run(program, "--xla_cpu_enable_concurrency_optimized_scheduler=true --xla_dump_to=/dev/null", timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["--xla_cpu_enable_concurrency_optimized_scheduler=true", "--xla_dump_to=/dev/null"]
    result = _run(program, "--xla_dump_to=/dev/null", timeout=120)
    assert result.stdout.split() == ["--xla_dump_to=/dev/null", "--xla_cpu_enable_concurrency_optimized_scheduler=false"]


GUARD = "from ffr_jax._dynamics._xla_flags import avoid_batched_lapack_deadlock as a; a()"


def test_the_guard_after_jax_started_warns_that_it_is_not_in_effect():
    result = _run("import jax.numpy as jnp; jnp.ones(2).sum()\n" + GUARD, None, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "JAX's backend started before" in result.stderr
    result = _run(GUARD + "\nimport jax.numpy as jnp; jnp.ones(2).sum()", None, timeout=120)
    assert "backend started" not in result.stderr


def test_batched_sharded_map_warns_without_the_guard():
    program = ("import warnings, jax.numpy as jnp, ffr_jax as fj\n"
               "with warnings.catch_warnings(record=True) as w:\n"
               "    warnings.simplefilter('always')\n"
               "    fj.sharded_map(lambda x: x * 2.0, batch_size=2)\n"
               "print(any('concurrency_optimized_scheduler' in str(m.message) for m in w))")
    assert _run(program, None, timeout=120).stdout.split() == ["True"]
    assert _run(program, "--xla_cpu_enable_concurrency_optimized_scheduler=false", timeout=120).stdout.split() == ["False"]


def test_program_options_turn_the_scheduler_and_fusion_emitters_off_unless_the_user_set_them(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    assert program_options("cpu") == {SCHEDULER_OPTION: False, FUSION_OPTION: False}
    assert program_options("gpu") == {} and program_options("cuda") == {}
    monkeypatch.setenv("XLA_FLAGS", f"--{SCHEDULER_OPTION}=true --{FUSION_OPTION}=true")
    assert program_options("cpu") == {}, "a setting of the user's is kept"
    monkeypatch.setenv("XLA_FLAGS", f"--{SCHEDULER_OPTION}=true")
    assert program_options("cpu") == {FUSION_OPTION: False}, "each option on its own"
