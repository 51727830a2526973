"""`fj.objective(case, x)` kept between processes as two programs split at the scene (issue 28): the FE stage and the
solve, so that a case whose FE stage cannot be exported (SciPy's Lanczos modes, a host callback) still loads its solve
in a later process instead of tracing and compiling it. A module of its own: tracing for export clears JAX's
in-memory caches of the process (`ffr_jax/_sensitivity/_cached.py`), which would make the shared programs of other
modules compile again. Slow: two compiles of a small Lanczos case's objective.
"""

import pytest

import ffr_jax as fj
from ffr_jax import _api
from ffr_jax._sensitivity import _cached as cached


@pytest.mark.slow
def test_a_case_objective_keeps_its_solve_when_its_fe_stage_cannot_be_exported(tmp_path, monkeypatch):
    # `fj.objective(case, x)` with SciPy's Lanczos modes (a host callback in the FE stage): the FE stage is compiled in
    # every process, the solve is exported once and loaded by later processes (here: the in-process programs
    # forgotten), not traced again. Before, the whole objective was one program that could not be exported, traced and
    # compiled again in every process. psi against the one-program path (`FFR_JAX_NO_CACHE`): the same arithmetic with
    # the scene passed between two programs instead of inside one, so they differ by round-off in XLA's fusion at
    # most: 1e-13 relative is ~500 ulps, far below the 1e-10 solve tolerance that a wrong scene would exceed.
    case = fj.cases.slider_crank(12, 2, 2, 0.05, modal_solver=fj.LanczosModes())
    x = case.initial_design(0.5).at[0].set(0.3)
    monkeypatch.setenv("FFR_JAX_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("FFR_JAX_NO_CACHE", raising=False)
    # The package's programs only: JAX's persistent cache stays off for the rest of this worker (tests/conftest.py).
    monkeypatch.setattr(_api, "use_persistent_cache", lambda directory: False)
    first = float(fj.objective(case, x))
    programs = tmp_path / "programs"
    assert len(list(programs.glob("*.unexportable"))) == 1, "the FE stage (a host callback) is noted as such"
    assert len(list(programs.glob("*.jaxexport"))) == 1, "the solve is exported"
    monkeypatch.setattr(cached, "_KEPT", {})
    exported = []
    monkeypatch.setattr(cached, "_export", lambda *args: exported.append(args) or None)
    again = float(fj.objective(case, x))
    assert not exported, "a later process traced a program for export again"
    assert sum(kept.loaded for kept in cached._KEPT.values()) == 1, "the solve is loaded, the FE stage compiled"
    assert again == first  # the same exported solve compiled by the same XLA
    monkeypatch.setenv("FFR_JAX_NO_CACHE", "1")
    one_program = float(fj.objective(case, x))
    assert abs(first - one_program) <= 1e-13 * abs(one_program), (first, one_program)
