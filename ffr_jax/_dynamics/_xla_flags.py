"""An XLA setting that batched dense modal analyses need on CPU, set before JAX starts its backend.

A deadlock of jaxlib's CPU runtime (jax/jaxlib 0.10.2): a batched LAPACK kernel (`cholesky`,
`eigh`, ... under `jax.vmap`) splits its batch over XLA's intra-op thread pool and blocks one pool
thread until the pieces are done. XLA's concurrency-optimised scheduler runs independent
operations at the same time; when as many batched LAPACK kernels run at once as the pool has
threads (two on a 2-core machine), every pool thread waits and none runs the pieces: the program
hangs at 0 % CPU. In this package it happens whenever dense modal analyses are batched with
independent branches, e.g. `jax.vmap` over designs of a difference quotient `f(x + h e) - f(x - h e)`
(a test of the frequency constraint hung so). Reproducer: 80 x 80 Cholesky factors of a batch of 48,
two independent ones per program, hung in 3 of 3 runs (and 3 of 3 other shapes and op mixes); with the
scheduler off, 0 of 10 runs hung.

On a loaded machine the scheduler also slows the package's own programs down: they are long sequences of
tiny operations (a Rosenbrock step of the reference case is ~10,000 of them on 13-vectors), which it
spreads over the thread pool, so that steps wait on the pool's hand-offs (the reference gradient's later
call at load 11.7: 12.2 s with it off, 16.1 s on; at load 1.7-3.5 no difference, 2.7-4.0 s either way:
benchmarks/RESULTS.md, "Default route"). So the programs the package compiles itself (the kept
programs of `fj.value_and_grad` and `fj.make_objective`, `ffr_jax/_sensitivity/_cached.py`) are
compiled with it off through `program_options` — a per-program XLA option, no environment edit —
unless the user's `XLA_FLAGS` set it. `import ffr_jax` does not touch the environment: the flag is set
where batched modal analyses run — the `ffr-jax` command sets it before JAX starts, and
[`sharded_map`][] with a `batch_size` warns when it is missing. A Python user who `jax.vmap`s dense
modal analyses in programs of their own sets it before starting Python:
`XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false`.
"""

import functools
import os
import warnings


DEADLOCK_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
SCHEDULER_OPTION = "xla_cpu_enable_concurrency_optimized_scheduler"
# XLA's CPU fusion emitters (the MLIR-based code generator, on by default in jaxlib 0.10) spend most of a first
# call's compile on the package's programs: long chains of tiny operations, thousands of small fusions. With the
# older emitters XLA's part of a first call was 24-39 % shorter on every shipped case (the reference gradient's
# 56.8 -> 34.5 s on one core), later calls as fast or faster, the numbers equal to round-off (benchmarks/RESULTS.md,
# "Compile time with XLA's older CPU fusion emitters"). So the package's own programs are compiled with them off,
# unless the user's XLA_FLAGS say otherwise.
FUSION_OPTION = "xla_cpu_use_fusion_emitters"


@functools.cache
def _known_option(name: str, value: bool) -> bool:
    """Whether this jaxlib's CPU compiler takes the option `name` (a later XLA may drop it): a scalar program
    compiled with it, once per process."""
    import jax

    try:
        jax.jit(lambda: 0.0).lower().compile({name: value})
    except Exception:  # noqa: BLE001 — an unknown or refused option: the programs compile without it
        return False
    return True


def program_options(platform: str) -> dict[str, bool]:
    """XLA options for a program the package compiles itself on `platform` (`Lowered.compile`'s
    `compiler_options`): on CPU the concurrency-optimised scheduler off (module docstring) and the older
    fusion emitters (`FUSION_OPTION`: XLA's part of a first call 24-39 % shorter, run time unchanged), each unless the
    user's `XLA_FLAGS` set that option either way; none elsewhere."""
    if platform != "cpu":
        return {}
    flags = os.environ.get("XLA_FLAGS", "")
    options = {}
    if SCHEDULER_OPTION not in flags:
        options[SCHEDULER_OPTION] = False
    if FUSION_OPTION not in flags and _known_option(FUSION_OPTION, False):
        options[FUSION_OPTION] = False
    return options


def add_flag(flag: str) -> bool:
    """Append `flag` to `XLA_FLAGS` unless the user's `XLA_FLAGS` already sets that option; whether it did."""
    name = flag.split("=", 1)[0]
    current = os.environ.get("XLA_FLAGS", "")
    if name in current:
        return False
    os.environ["XLA_FLAGS"] = f"{current} {flag}".strip()
    return True


def _backend_started() -> bool:
    from jax._src import xla_bridge  # private: whether a backend exists already (no public query)

    return bool(getattr(xla_bridge, "_backends", {}))


def avoid_batched_lapack_deadlock() -> None:
    """Turn XLA's concurrency-optimised CPU scheduler off (see the module docstring): called by the
    `ffr-jax` command before JAX starts; warns when JAX's backend runs already without it."""
    if add_flag(DEADLOCK_FLAG) and _backend_started():
        warnings.warn(f"JAX's backend started before {DEADLOCK_FLAG} was added to XLA_FLAGS, so it does not apply "
                      "in this process: batched dense modal analyses under jax.vmap may hang "
                      "(ffr_jax/_dynamics/_xla_flags.py). Set XLA_FLAGS before starting Python.",
                      RuntimeWarning, stacklevel=3)


def warn_if_unguarded(where: str) -> None:
    """A `RuntimeWarning` when `XLA_FLAGS` lacks the flag on a CPU backend (batched LAPACK kernels may hang)."""
    import jax

    if DEADLOCK_FLAG.split("=", 1)[0] in os.environ.get("XLA_FLAGS", "") or jax.default_backend() != "cpu":
        return
    warnings.warn(f"{where}: batched dense modal analyses under jax.vmap can deadlock XLA's CPU thread pool "
                  f"(jaxlib 0.10); start Python with XLA_FLAGS={DEADLOCK_FLAG} (ffr_jax/_dynamics/_xla_flags.py), "
                  "or keep batch_size=None.", RuntimeWarning, stacklevel=3)
