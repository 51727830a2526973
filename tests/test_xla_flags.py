"""The package's guard against a deadlock of jaxlib's CPU runtime (ffr_jax/_xla_flags.py).

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

ROOT = Path(__file__).resolve().parents[1]

PROGRAM = """
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


def test_a_setting_of_the_user_is_kept():
    program = "import ffr_jax, os; print(os.environ['XLA_FLAGS'])"
    result = _run(program, "--xla_cpu_enable_concurrency_optimized_scheduler=true --xla_dump_to=/dev/null", timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["--xla_cpu_enable_concurrency_optimized_scheduler=true", "--xla_dump_to=/dev/null"]
    result = _run(program, "--xla_dump_to=/dev/null", timeout=120)
    assert result.stdout.split() == ["--xla_dump_to=/dev/null", "--xla_cpu_enable_concurrency_optimized_scheduler=false"]


def test_importing_after_jax_started_warns_that_the_guard_is_not_in_effect():
    result = _run("import jax.numpy as jnp; jnp.ones(2).sum()\nimport ffr_jax", None, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "JAX's backend started before ffr_jax was imported" in result.stderr
    result = _run("import ffr_jax, jax.numpy as jnp; jnp.ones(2).sum()", None, timeout=120)
    assert "backend started" not in result.stderr
