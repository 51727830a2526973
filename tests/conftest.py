"""Test configuration: float64 and strict dtype promotion for every test.

`ffr_jax` is deliberately not imported here: the jaxtyping import hook from `addopts`
(`--jaxtyping-packages=ffr_jax,...`) must be installed before the package is first imported,
and root conftest files load before that hook.
"""

import os

import jax


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# XLA compilation dominates the suite's run time (diffrax solves and their gradients take tens of
# seconds to compile); JAX's persistent cache keeps compiled programs between runs on one machine.
# FFR_JAX_TEST_CACHE= (empty) turns it off.
_cache = os.environ.get("FFR_JAX_TEST_CACHE", os.path.join(os.path.expanduser("~"), ".cache", "ffr_jax", "xla"))
# The CLI (run in-process by some tests) turns on its own persistent cache: point it at the same
# directory, or keep it off when the tests run without a cache.
if _cache:
    os.environ.setdefault("FFR_JAX_CACHE_DIR", _cache)
else:
    os.environ["FFR_JAX_NO_CACHE"] = "1"
if _cache:
    jax.config.update("jax_compilation_cache_dir", _cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    # Subprocesses (the CLI tests, the notebook kernels) read the same settings from the environment.
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", _cache)
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
