"""Test configuration: float64 and strict dtype promotion for every test; how pytest-xdist splits the suite.

`ffr_jax` is deliberately not imported here: the jaxtyping import hook from `addopts`
(`--jaxtyping-packages=ffr_jax,...`) must be installed before the package is first imported,
and root conftest files load before that hook.
"""

import os

import pytest
from suite_plan import LONGEST_FIRST, SLOW_FOR_THE_BUDGET, group


# XLA settings for the suite, set before JAX's backend starts. Compilation dominates the suite (each
# diffrax solve and gradient is compiled once per structure and process), so the suite trades run time
# for compile time: measured on tests/test_problem.py alone, one process, two such runs at once on
# 2 cores: 246 s in the suite before -> 161 s without XLA's new fusion emitters -> 147 s with LLVM at
# -O0 too (the rigid adjoint + autodiff setup 116 -> 79 -> 70 s; a compiled gradient then runs 2-3x
# slower). The numbers the tests check do not depend on it beyond round-off: every tolerance is argued
# from the accuracy of its check (tests/TOLERANCES.md), not from one compiler's last bits.
# FFR_JAX_TEST_XLA_DEFAULTS=1 runs the suite with XLA's defaults instead (as users get them).
# The deadlock guard of the ffr-jax command (ffr_jax/_dynamics/_xla_flags.py: a deadlock of batched LAPACK kernels
# under vmap) is set here for every test (the tests vmap dense modal analyses; import ffr_jax does not set it).
# (ffr_jax._dynamics._xla_flags.add_flag cannot be imported here: see the module docstring on the import hook.)
_FLAGS = ["--xla_cpu_enable_concurrency_optimized_scheduler=false"]  # = ffr_jax._dynamics._xla_flags.DEADLOCK_FLAG
# A second guard, a precaution: jaxlib 0.10.2's LAPACK kernels split a batch over XLA's intra-op thread pool and block
# waiting for the parts; when the pool's threads all sit in such kernels nothing runs (seen this session: batched trsm
# and getrf under vmap hung the spatial slider-crank's and a JointLoad test's worker at 0 % CPU, scheduler flag set;
# probably also why the CI of stop 34 ran past its 90-minute cap). jaxlib 0.11.1 compiles that path out of open-source builds; 0.10.2
# is the newest on the registry here. Single-threaded Eigen is the workaround other projects report for such pool
# stalls; it is not shown to prevent this one (no small reproducer), and should cost the suite little (not measured
# separately): two workers already occupy the two cores. The dependent solves of up to 16 x 16 avoid LAPACK altogether
# (ffr_jax/_dynamics/_small_linalg.py), the multipliers' derivative too (ffr_jax/_outputs/_multipliers.py).
_FLAGS += ["--xla_cpu_multi_thread_eigen=false"]
if not os.environ.get("FFR_JAX_TEST_XLA_DEFAULTS"):
    _FLAGS += ["--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=0",
               "--xla_llvm_disable_expensive_passes=true"]
for _flag in _FLAGS:  # each only where the user's XLA_FLAGS does not set that option
    if _flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}".strip()

# Single-threaded XLA: FFR_JAX_TEST_ONE_CORE_PER_WORKER=1 pins each pytest-xdist worker to one CPU of its
# own before JAX starts, so XLA's intra-op thread pool (sized by the CPUs a process may use) has one
# thread. (`XLA_FLAGS=intra_op_parallelism_threads=1` does not change that pool in jaxlib 0.10.2.)
# Workers only: the controlling process must not pin itself, its workers would inherit it.
_worker = os.environ.get("PYTEST_XDIST_WORKER")
if os.environ.get("FFR_JAX_TEST_ONE_CORE_PER_WORKER") and _worker and hasattr(os, "sched_setaffinity"):
    _cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {_cpus[int(_worker.removeprefix("gw")) % len(_cpus)]})

import jax  # noqa: E402  (after XLA_FLAGS)


# Python's garbage collector: the package pauses it during its own first calls (ffr_jax/_compiled.py,
# `collector_paused`); the tests' own jax.jit calls (and eqx.filter_jit functions called directly) trace with it on,
# in a worker whose heap holds every earlier test's programs. The suite raises only the first threshold (young
# objects scanned every 100,000 net allocations instead of 700); the older generations keep Python's thresholds, so
# full collections, and memory, stay as with the defaults. benchmarks/RESULTS.md, "Python's garbage collector
# during tracing", has what each setting measured.
import gc  # noqa: E402

gc.set_threshold(100_000, 10, 10)

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# JAX's persistent compilation cache is OFF for the suite unless FFR_JAX_TEST_CACHE names a directory.
# It keeps only programs without host callbacks (every diffrax solve, through its `eqx.error_if`
# checks, is compiled afresh in each process, cache or not), so it saves little here, and a run of the
# README command with the cache a first run had left (fresh clone, 25d7f18) lost a pytest-xdist worker
# to a segfault in libgcc_s's unwinder and then hung. Until that is understood, each run compiles
# everything itself: the same work on every machine, whatever cache it holds.
_cache = os.environ.get("FFR_JAX_TEST_CACHE", "")
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


# pytest-xdist groups, their order and the slow set for the budget: tests/suite_plan.py.
# A wrapper runs before every plain implementation whatever the plugins' registration order, so the groups
# are in place when pytest-xdist's own `pytest_collection_modifyitems` reads them. (With pytest 9.2 and
# pytest-xdist 3.8 the groups are lost all the same: see the pin in pyproject.toml and
# tests/test_suite_setup.py; the cold suite then took 624 s instead of ~450 s.)
@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.startswith(SLOW_FOR_THE_BUDGET):
            item.add_marker(pytest.mark.slow)
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(group(item), len(rank)))  # stable: module order kept within a group
    for item in items:
        item.add_marker(pytest.mark.xdist_group(group(item)))
    return (yield)
