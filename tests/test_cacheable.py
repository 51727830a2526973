"""The design gradient as cacheable programs (`ffr_jax._sensitivity._cached`, what `ffr-jax gradient` runs).

Checked on the small case family: the split programs give the adjoint gradient of `value_and_grad`;
an exported program saved by one compilation is loaded by the next without tracing and gives the
same numbers bit for bit; equinox's checks raise again after the `nan`-mode tracing; a static part
without a stable name is never keyed.
"""

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ATOL, RTOL, adjoint_value_and_grad, random_design, small_case

import ffr_jax as fj
from ffr_jax._dynamics._xla_flags import SCHEDULER_OPTION
from ffr_jax._sensitivity import _cached as cached
from ffr_jax._sensitivity._cached import _program_key, compile_value_and_grad


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    case = small_case()
    x = random_design(case, 0)
    directory = tmp_path_factory.mktemp("programs")
    fun, info = compile_value_and_grad(case, x, fj.Adjoint(), rtol=RTOL, atol=ATOL, export_dir=directory)
    return case, x, directory, fun, info


def test_split_programs_give_the_adjoint_gradient(compiled):
    case, x, directory, fun, info = compiled
    assert not info["exported_loaded"], "nothing to load on the first compilation"
    # The FE stage, the solves and the FE stage's VJP: three programs kept.
    assert len(list(directory.glob("*.jaxexport"))) == 3, "the three programs are saved"
    psi, grad = fun(x)
    psi_ref, grad_ref = adjoint_value_and_grad(case, x)
    # The same computation (the design gradient is the scene gradient pulled back through the design
    # map: `AbstractSensitivity.value_and_grad_design`) compiled as other programs: XLA may order
    # floating-point sums differently, and the adaptive step control can turn that round-off into
    # another step sequence, so the two agree to the solves' accuracy: forward rtol 1e-10 (psi:
    # allowed 1e-9), backward rtol 1e-8 (gradient: allowed 1e-7 relative, max-norm).
    np.testing.assert_allclose(float(psi), float(psi_ref), rtol=1e-9)
    assert np.max(np.abs(grad - grad_ref)) <= 1e-7 * np.max(np.abs(grad_ref)), "gradient vs value_and_grad"


def test_a_saved_program_is_loaded_without_tracing(compiled, monkeypatch):
    case, x, directory, fun, _ = compiled
    jax.clear_caches()
    # The kept programs are compiled with the package's XLA options (`_dynamics/_xla_flags.py`): on CPU the
    # concurrency-optimised scheduler off unless the user's XLA_FLAGS set it (the suite's do: removed here).
    monkeypatch.setenv("XLA_FLAGS", " ".join(f for f in os.environ.get("XLA_FLAGS", "").split()
                                             if SCHEDULER_OPTION not in f))
    options = []
    compile_lowered = jax.stages.Lowered.compile
    monkeypatch.setattr(jax.stages.Lowered, "compile",
                        lambda self, compiler_options=None: options.append(compiler_options)
                        or compile_lowered(self, compiler_options))
    again, info = compile_value_and_grad(case, x, fj.Adjoint(), rtol=RTOL, atol=ATOL, export_dir=directory)
    assert info["exported_loaded"], "the second compilation loads the exported program"
    expected = {SCHEDULER_OPTION: False} if jax.default_backend() == "cpu" else {}
    assert len(options) == 3 and all(o == expected for o in options), options
    x2 = random_design(case, 1)
    # The same StableHLO compiled by the same XLA on the same machine: bit-identical results.
    for a, b in zip(jax.tree_util.tree_leaves(fun(x2)), jax.tree_util.tree_leaves(again(x2))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_checks_raise_again_after_nan_mode_tracing(compiled):
    # `compiled` traced the scene gradient with equinox's checks as NaN; a new trace must raise.
    f = eqx.filter_jit(lambda v: eqx.error_if(v, v < 0, "negative"))
    with pytest.raises(eqx.EquinoxRuntimeError, match="negative"):
        jax.block_until_ready(f(jnp.asarray(-1.0)))


def _named(t):
    return t


def test_a_lambda_in_the_static_part_is_never_keyed():
    leaves, treedef = jax.tree_util.tree_flatten(jnp.zeros(3))
    assert _program_key((_named,), treedef, leaves, {}) is not None, "a named function has a stable key"
    assert _program_key((lambda t: t,), treedef, leaves, {}) is None, "a lambda has none"


def test_a_function_counts_by_its_code_and_a_closure_is_never_keyed():
    # Two functions of one name with different bodies (a user's integrand edited between two runs, or two
    # scripts) must not share a kept program; a closure's behaviour depends on what it captured.
    leaves, treedef = jax.tree_util.tree_flatten(jnp.zeros(3))
    namespace_a, namespace_b = {}, {}
    exec("def integrand(t):\n    return t", namespace_a)
    exec("def integrand(t):\n    return 2.0 * t", namespace_b)
    key_a = _program_key((namespace_a["integrand"],), treedef, leaves, {})
    key_b = _program_key((namespace_b["integrand"],), treedef, leaves, {})
    assert key_a is not None and key_b is not None and key_a != key_b

    def factory(w):
        def integrand(t):
            return w * t
        return integrand

    assert _program_key((factory(1.0),), treedef, leaves, {}) is None


# A function whose code holds a generator expression and a set of string constants: the generator's code object
# shows its address in its `repr`, and the set's `repr` follows string hashing, both different in every process.
_NESTED_SOURCE = """
def guess(t, names):
    parts = tuple(2.0 * t for _ in range(3))
    return parts if names in {"crank", "coupler", "rocker"} else None
"""


def _nested_token():
    namespace = {"__name__": "user_module"}
    exec(_NESTED_SOURCE, namespace)
    return cached._function_token(namespace["guess"])


def test_a_function_has_the_same_key_in_another_process():
    # The four-bar's dependent-coordinate guess holds a generator expression; until 27 Nov its key came from the
    # `repr` of its constants, the generator's address among them, so a second process never found the programs a
    # first had kept and traced and exported them again (the four-bar's second process 27 s, 12.6 s of it tracing).
    import subprocess
    import sys

    from ffr_jax.cases._four_bar import _four_bar_guess

    here = (cached._function_token(_four_bar_guess), _nested_token())
    assert None not in here and not any(" at 0x" in token for token in here), here
    script = ("import sys; sys.path.insert(0, %r); import test_cacheable as t; "
              "from ffr_jax.cases._four_bar import _four_bar_guess; "
              "print(t.cached._function_token(_four_bar_guess)); print(t._nested_token())") % os.path.dirname(__file__)
    env = dict(os.environ, PYTHONHASHSEED="12345")  # another string hashing than this process's (random) one
    other = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, check=True)
    assert tuple(other.stdout.split("\n")[:2]) == here, (other.stdout, other.stderr[-2000:], here)


def test_a_program_is_keyed_by_the_platform_it_runs_on(monkeypatch):
    # Found on an H100 (RESULTS "GPU"): a program exported by a GPU process was loaded by a CPU process
    # sharing the cache folder, and JAX refused it ("exported for platforms ('cuda',) but it is used on
    # ('cpu',)"). The key must differ between platforms.
    leaves, treedef = jax.tree_util.tree_flatten(jnp.zeros(3))
    here = _program_key((_named,), treedef, leaves, {})
    monkeypatch.setattr(jax, "default_backend", lambda: "cuda" if jax.devices()[0].platform == "cpu" else "cpu")
    assert _program_key((_named,), treedef, leaves, {}) != here


def _host_sum(v):
    """A program with a host callback (like the FE stage with SciPy's Lanczos solver): it cannot be exported."""
    return jax.pure_callback(lambda a: np.asarray(np.sum(a), a.dtype), jax.ShapeDtypeStruct((), v.dtype), v) + v


def test_a_program_that_cannot_be_exported_is_not_tried_again(tmp_path, monkeypatch):
    # The first call finds the program not exportable (a host callback) and leaves a note with the reason; a later
    # process (here: the in-process programs forgotten) compiles it directly, without tracing it for export again.
    # The note would be ignored if the key differed, so the check also shows that the key is stable.
    v = jnp.arange(3.0)
    first = cached.kept_call(_host_sum, (v,), tmp_path, "a host sum")
    notes = list((tmp_path / "programs").glob("*.unexportable"))
    assert len(notes) == 1 and "callback" in notes[0].read_text(), notes
    assert not list((tmp_path / "programs").glob("*.jaxexport")), "nothing exported"
    monkeypatch.setattr(cached, "_KEPT", {})

    tried = []
    monkeypatch.setattr(cached, "_export", lambda *args: tried.append(args) or None)
    again = cached.kept_call(_host_sum, (v,), tmp_path, "a host sum")
    assert not tried, "the export was tried again"
    np.testing.assert_array_equal(np.asarray(first), np.asarray(again))
    np.testing.assert_array_equal(np.asarray(again), np.asarray(v) + 3.0)


# --- from Python: a second process loads the compiled gradient (issue 28) -------------------------
PROGRAM = """
import json, logging, sys, time
records = []
class Keep(logging.Handler):
    def emit(self, record):
        records.append(record.getMessage())
logging.getLogger("ffr_jax").addHandler(Keep())
logging.getLogger("ffr_jax").setLevel(logging.INFO)
import numpy as np
import ffr_jax as fj
from ffr_jax._sensitivity._cached import cache_events
events = cache_events()
case = fj.cases.slider_crank(4, 2, 2, 0.05)
x = case.initial_design(0.5)
start = time.perf_counter()
psi, grad = fj.value_and_grad(case, x)
first = time.perf_counter() - start
start = time.perf_counter()
fj.value_and_grad(case, x * 0.9)
later = time.perf_counter() - start
objective = float(fj.objective(case, x))
print(json.dumps(dict(psi=float(psi), grad=np.asarray(grad).tolist(), first=first, later=later, log=records,
                      objective=objective,
                      xla=cache_events())))
"""


def _process(directory):
    import json
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("FFR_JAX_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env["FFR_JAX_CACHE_DIR"] = str(directory)
    out = subprocess.run([sys.executable, "-c", PROGRAM], env=env, capture_output=True, text=True, timeout=1200)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_a_second_process_loads_the_gradient_instead_of_compiling(tmp_path):
    # Two fresh processes call fj.value_and_grad(case, x) with the same case and settings; the cache is on by
    # default (the suite turns it off for itself; here it points at an empty directory).
    first, second = _process(tmp_path), _process(tmp_path)
    getting = [m for m in first["log"] if m.startswith("getting the design gradient")]
    assert len(getting) == 1 and "compiling it" in getting[0], first["log"]
    getting = [m for m in second["log"] if m.startswith("getting the design gradient")]
    assert len(getting) == 1 and "loading it from the cache" in getting[0], second["log"]
    assert not any(m.startswith("compiling") for m in second["log"]), second["log"]
    assert any(m.startswith("compiling the objective of a case") for m in first["log"]), first["log"]
    assert any(m.startswith("loading the objective of a case") for m in second["log"]), second["log"]
    assert second["objective"] == first["objective"]
    assert second["xla"]["cache_hits"] >= 1, second["xla"]  # the scene gradient's XLA program, from disk
    # The same exported program compiled by the same XLA: bit-identical numbers.
    assert second["psi"] == first["psi"] and second["grad"] == first["grad"]
    # Loading skips tracing and XLA's compilation of the solves: measured 116 s -> 9.7 s on a loaded 2-core
    # machine (load 10). Half is a bound that only a second compilation of the solves would break.
    assert second["first"] < 0.5 * first["first"], (first["first"], second["first"])


@pytest.mark.slow
def test_a_failed_solve_in_a_kept_program_raises_the_package_error(tmp_path, monkeypatch):
    # The kept programs run equinox's checks as NaN; a solve that fails there (here the step budget) must end
    # in the package's own error, as with the checks raising, and soon: the backward solve of a failed forward
    # spans no time (before, it spent its own budget on NaN: issue 32's CLI hang).
    monkeypatch.delenv("FFR_JAX_NO_CACHE", raising=False)
    monkeypatch.setenv("FFR_JAX_CACHE_DIR", str(tmp_path))
    case = fj.cases.slider_crank(4, 2, 2, 0.1)
    with pytest.raises(fj.SimulationError, match="maximum number of solver steps"):
        fj.value_and_grad(case, case.initial_design(0.5), "adjoint", max_steps=20)
    assert list((tmp_path / "programs").glob("*.jaxexport")), "the gradient went through the kept programs"
