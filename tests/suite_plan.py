"""How the suite is run: which tests share a pytest-xdist worker, the order the work is handed out in, and
which tests go to the slow set (`-m slow`, which CI runs after the README command) to keep the README command
within its 5-minute budget on a fresh 2-core machine. Read by `conftest.py`."""

# --- pytest-xdist: which tests share a worker, and in which order the work is handed out ---------
# `pyproject.toml` runs the suite on two workers with `--dist loadgroup`: every test carries an
# `xdist_group`, and a group runs whole on one worker, so that its module-scoped fixtures and the
# programs compiled in `helpers.py` are built once. The modules that run the family's shared
# programs (`helpers.adjoint_value_and_grad`, `helpers.tight_objective`, the family's plain autodiff call of
# test_sensitivity and test_stiff_route) form one group; every other
# module is its own group. Groups are handed out longest first (measured cold-cache time on two
# cores, largest first), which keeps the two workers evenly loaded; new modules go last.
# (`test_adjoint_quadrature` runs the family member's own solves, not the shared programs, but builds the
# same case, `helpers.small_case`, which is cached per process.) The order after issues 12 and 13
# (design subpackage, problem type): the older modules keep their measured ranking; test_problem and the
# test_design_* modules are placed by their single-process times on the shared, loaded machine (only
# the ranking is meant; benchmarks/RESULTS.md, "Test modules one at a time"); the modules of issues 14-17
# by their authors' loaded cold times (test_discrete_adjoint, ~20 s, was left out and so handed out last).
# The slow set (`-m slow`, CI) is ordered by the same list: its two longest modules (the spatial slider-crank's
# programs, the stress and torque gradients; minutes each on one worker) come first, so that the rest fills the
# other worker around them instead of both waiting for them at the end (the CI of stop 34 ran past its 90-minute cap
# with them handed out last).
SHARED_PROGRAMS = ("test_sensitivity", "test_hard_cases", "test_adjoint_quadrature", "test_cacheable", "test_stiff_route")
LONGEST_FIRST = ("test_spatial_flexible_slider_crank", "test_stress_objective", "family", "test_problem", "test_two_links", "test_notebooks", "test_design_map", "test_conditions",
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
SLOW_FOR_THE_BUDGET = (
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
    # Fourth cut: 357 s with 550 tests after issues 26, 27, 29, 31, 32 (a clean clone of dfe3429, load ~3, with
    # --durations): these go, each subject still checked by default elsewhere:
    "tests/test_dynamics.py::test_four_bar_turns_full_circles_on_its_branch",  # (25 s); four-bar dynamics: slow set
    "tests/test_hard_cases.py::test_crossing_retained_eigenvalues",  # (26 s); test_sensitivity's crossing test stays
    "tests/test_optimize_defaults.py::test_default_mma_lowers_psi_with_the_volume_held",  # (22 s); test_optimize's MMA
    "tests/test_solvers.py::test_psi_of_a_small_slider_crank_agrees_with_dopri8",  # (14 s); Rodas orders stay
    "tests/test_simulation_errors.py::test_partition_regular_away_from_the_dead_point",  # (13 s); the dead-point rows stay
    "tests/test_stresses.py::test_stresses_along_the_motion_refuse_a_rigid_body_index",  # (7 s); the stress checks stay
    # Fifth cut: 361.2 s with 649 tests (fresh-test at b50bccb, idle machine), after the stiff route's reference became
    # the family's autodiff program (-47 worker-s); a run of the default suite with --durations (two workers, one
    # core shared with a pinned benchmark) gave the worker-seconds in brackets:
    "tests/test_accelerations_derivative.py::test_custom_derivative_of_accelerations_equals_the_direct_one[unrolled]",
    # (32 s); every gradient check of the default suite runs through that derivative (adjoint vs autodiff vs FD)
    "tests/test_effects.py::test_geometric_stiffening_off_is_not_traced",  # (15 s); gravity, damping off: stay
    "tests/test_xla_flags.py::test_a_setting_of_the_user_is_kept",  # (8.5 s; two fresh processes)
    "tests/test_xla_flags.py::test_the_guard_after_jax_started_warns_that_it_is_not_in_effect",  # (7.4 s); the guard stays
    # After it: 249.2 s and 233.6 s with 653 tests (fresh-test at bbaea3e and 133f9e6, idle machine).
)


def group(item) -> str:
    module = item.path.stem
    return "family" if module in SHARED_PROGRAMS else module
