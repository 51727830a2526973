"""Test configuration: float64 and strict dtype promotion for every test; how pytest-xdist splits the suite.

`ffr_jax` is deliberately not imported here: the jaxtyping import hook from `addopts`
(`--jaxtyping-packages=ffr_jax,...`) must be installed before the package is first imported,
and root conftest files load before that hook.
"""

import os

import pytest


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


# --- pytest-xdist: which tests share a worker, and in which order the work is handed out ---------
# `pyproject.toml` runs the suite on two workers with `--dist loadgroup`: every test carries an
# `xdist_group`, and a group runs whole on one worker, so that its module-scoped fixtures and the
# programs compiled in `helpers.py` are built once. The modules that run the family's shared
# programs (`helpers.adjoint_value_and_grad`, `helpers.tight_objective`) form one group; every other
# module is its own group. Groups are handed out longest first (measured cold-cache time on two
# cores, largest first), which keeps the two workers evenly loaded; new modules go last.
# (`test_adjoint_quadrature` runs the family member's own solves, not the shared programs, but builds the
# same case, `helpers.small_case`, which is cached per process.) The order after issues 12 and 13
# (design subpackage, problem type): the older modules keep their measured ranking; test_problem and the
# test_design_* modules are placed by their single-process times on the shared, loaded machine (only
# the ranking is meant; benchmarks/RESULTS.md, "Test modules one at a time"); the modules of issues 14-17
# by their authors' loaded cold times (test_discrete_adjoint, ~20 s, was left out and so handed out last).
_SHARED_PROGRAMS = ("test_sensitivity", "test_hard_cases", "test_adjoint_quadrature", "test_cacheable")
_LONGEST_FIRST = ("family", "test_problem", "test_two_links", "test_notebooks", "test_design_map", "test_conditions",
                  "test_design_modes", "test_dynamics", "test_spatial_gradient", "test_optimize", "test_io", "test_outputs_any_mesh", "test_cli_user_case", "test_optimize_defaults",
                  "test_design_invariant",
                  "test_stiff_route", "test_mma", "test_solvers", "test_accelerations_derivative", "test_reactions", "test_discrete_adjoint",
                  "test_bad_input_fuzz", "test_simulation_errors", "test_spatial_rigid", "test_spatial_loop", "test_effects",
                  "test_link_four_bar", "test_constraints", "test_design_body_data", "test_design_geometry",
                  "test_bad_input", "test_two_links_optimize", "test_design_mesh", "test_design_filter",
                  "test_design_elements", "test_design_stacked", "test_small_linalg", "test_notebook_link",
                  "test_notebooks_optimize")


# The README's test command runs in at most 5 minutes on a fresh 2-core machine (issue 28); CI runs these
# after it with `-m slow`, so no check goes unrun. Whole modules or single tests, by the measured cost of their
# compiles (a run of the default suite with `--durations=0`, loaded machine, worker-seconds in brackets), each
# one whose subject the default suite still checks elsewhere:
_SLOW_FOR_THE_BUDGET = (
    "tests/test_two_links.py",              # two designed bodies (213 s); the dict design is test_design_map's
    "tests/test_adjoint_quadrature.py",     # the adjoint's quadrature variants (202 s); test_sensitivity checks the adjoint
    "tests/test_cacheable.py",              # the CLI's exported programs (140 s); test_cli_user_case runs the CLI
    "tests/test_conditions.py",             # operating conditions (138 s)
    "tests/test_notebooks.py::test_notebook_runs_at_small_size",  # two benchmark notebooks (84 s)
    "tests/test_problem.py::test_readme_own_mechanism_runs_and_its_gradient_is_right",  # its own adjoint (109 s)
    "tests/test_problem.py::test_trajectory_holds_every_coordinate_and_marker",  # (40 s)
    "tests/test_design_map.py::test_sharded_batch_equals_loop_over_designs",  # (20 s)
    "tests/test_dynamics.py::test_rigid_slider_crank_matches_closed_form_kinematics",  # (39 s)
    "tests/test_dynamics.py::test_free_rigid_slider_crank_follows_closed_form_kinematics",  # (13 s)
    "tests/test_dynamics.py::test_constraints_hold_along_trajectories[four_bar",  # (33 s); pendulum, slider-crank stay
    "tests/test_dynamics.py::test_minimal_accelerations_equal_lagrange_multiplier_dae[four_bar]",  # (26 s)
    # Second cut: the cold README command took 402 s (fresh-test at 965c4a7) after the first.
    # The README mechanism's adjoint (212 s); value_and_grad(problem) stays checked by test_spatial_gradient.
    "tests/test_problem.py::test_rigid_adjoint_equals_central_differences_on_every_parameter",
    "tests/test_problem.py::test_plain_calls_are_compiled_once",
    "tests/test_sensitivity.py::test_vmap_equals_per_design_calls",  # (61 s); test_design_map batches designs
    "tests/test_simulation_errors.py::test_singular_partition_is_an_error_not_a_nan",  # (23 s)
    "tests/test_effects.py::test_geometric_stiffening_stiffens_a_spinning_beam",  # (17 s)
    "tests/test_dynamics.py::test_mass_matrix_and_forces_equal_mesh_lagrangian[1-",  # seed 1 (18 s); seed 0 stays
    "tests/test_reactions.py",  # joint forces against a DAE and Newton-Euler (40 s)
    "tests/test_spatial_rigid.py::test_angle_driver_turns_a_hinged_body_through_full_turns",  # (14 s)
    # Third cut: 328.6 s after the second (fresh-test at c7b1202). The discrete adjoint's step transpose stays in
    # the default suite (the default route's own check); these go:
    "tests/test_stiff_route.py::test_stiff_route_gives_the_explicit_psi_and_gradient[adjoint]",  # (44 s)
    "tests/test_stiff_route.py::test_backward_jacobian_is_minus_the_transposed_jacobian",  # (10 s)
    "tests/test_sensitivity.py::test_central_differences_on_every_entry",  # (26 s); hard cases check against FD
    "tests/test_io.py::test_mma_run_with_volume_and_frequency_constraints",  # (17 s)
    "tests/test_constraints.py::test_frequency_constraint_value_and_gradient",  # (16 s)
    "tests/test_dynamics.py::test_mass_matrix_and_forces_equal_mesh_lagrangian[0-four_bar]",  # (14 s)
    "tests/test_dynamics.py::test_minimal_accelerations_equal_lagrange_multiplier_dae[rigid_slider_crank]",  # (17 s)
    "tests/test_accelerations_derivative.py::test_custom_derivative_of_accelerations_equals_the_direct_one[lapack]",
    "tests/test_hard_cases.py::test_crank_speed_at_first_resonance",  # (13 s)
    "tests/test_link_four_bar.py::test_cli_info_knows_the_scene",  # (12 s)
    "tests/test_optimize.py::test_psi_decreases_on_a_tiny_real_case_through_the_cli",  # (11 s)
    "tests/test_design_invariant.py::test_unstructured_rod_gives_the_slider_crank_psi_and_gradient",  # (13 s)
)


def _group(item) -> str:
    module = item.path.stem
    return "family" if module in _SHARED_PROGRAMS else module


# A wrapper runs before every plain implementation whatever the plugins' registration order, so the groups
# are in place when pytest-xdist's own `pytest_collection_modifyitems` reads them. (With pytest 9.2 and
# pytest-xdist 3.8 the groups are lost all the same: see the pin in pyproject.toml and
# tests/test_suite_setup.py; the cold suite then took 624 s instead of ~450 s.)
@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.startswith(_SLOW_FOR_THE_BUDGET):
            item.add_marker(pytest.mark.slow)
    rank = {name: k for k, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(_group(item), len(rank)))  # stable: module order kept within a group
    for item in items:
        item.add_marker(pytest.mark.xdist_group(_group(item)))
    return (yield)
