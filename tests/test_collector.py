"""Python's garbage collector is paused while the package traces a program, and left as the user had it after.

`ffr_jax/_compiled.py`: tracing allocates millions of objects that live until the program is lowered, and the
collector's scans of them cost ~30 % of the README mechanism's tracing time. The pause must cover the trace (seen
here from inside the traced function) and must not leak: the collector is on again after the call, also when the
call raised, and stays off when the user had turned it off.
"""

import gc

import jax.numpy as jnp
import pytest

from ffr_jax._compiled import Program, collector_paused
from ffr_jax._sensitivity._cached import kept_call


_SEEN: list[bool] = []


def _traced_double(x):
    _SEEN.append(gc.isenabled())  # runs once, while JAX traces the function
    return 2.0 * x


def _traced_failure(x):
    _SEEN.append(gc.isenabled())
    raise ValueError("a failure while tracing")


@pytest.fixture
def collector_on():
    was = gc.isenabled()
    gc.enable()
    _SEEN.clear()
    yield
    (gc.enable if was else gc.disable)()


def test_a_first_call_traces_with_the_collector_paused(collector_on):
    program = Program(_traced_double, "the double")
    out = program(jnp.arange(3.0))
    assert _SEEN == [False]
    assert gc.isenabled()
    assert list(out) == [0.0, 2.0, 4.0]  # exact: doubling small integers


def test_a_kept_program_is_traced_with_the_collector_paused(collector_on, tmp_path):
    out = kept_call(_traced_double, (jnp.arange(3.0),), tmp_path, "the double")
    assert out is not None, "the test function should have a key across processes"
    assert _SEEN and not any(_SEEN), _SEEN  # traced once for the export (and once more if not exportable)
    assert gc.isenabled()
    assert list(out) == [0.0, 2.0, 4.0]


def test_the_collector_is_restored_when_the_first_call_raises(collector_on):
    program = Program(_traced_failure, "the failure")
    with pytest.raises(ValueError, match="a failure while tracing"):
        program(jnp.arange(3.0))
    assert _SEEN == [False]
    assert gc.isenabled()


def test_a_collector_the_user_turned_off_stays_off(collector_on):
    gc.disable()
    with collector_paused():
        with collector_paused():  # nested: the inner pause changes nothing
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert not gc.isenabled()
    gc.enable()
    with collector_paused():
        with collector_paused():
            pass
        assert not gc.isenabled()  # the outer pause still holds after the inner one ends
    assert gc.isenabled()
