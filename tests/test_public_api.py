"""The public API (issue 29): every public name documented, the names of earlier releases still working
with a DeprecationWarning for one release, one call form of `simulate`."""

import importlib
import inspect
import warnings

import pytest

import ffr_jax as fj


def test_every_public_name_has_a_docstring():
    missing = [name for name in fj.__all__ if not inspect.getdoc(getattr(fj, name))]
    assert not missing, f"public names without a docstring: {missing}"


def test_all_lists_exactly_the_public_names():
    names = [n for n in dir(fj) if not n.startswith("_") and (n == "cases" or not inspect.ismodule(getattr(fj, n)))]
    assert sorted(fj.__all__) == sorted(names)
    assert not set(fj.__all__) & set(fj._DEPRECATED), "a deprecated name is still exported"


@pytest.mark.parametrize("name", sorted(fj._DEPRECATED))
def test_a_deprecated_name_still_works_and_says_what_to_use(name):
    module, attribute, instead = fj._DEPRECATED[name]
    with pytest.warns(DeprecationWarning, match=f"ffr_jax.{name} is deprecated"):
        obj = getattr(fj, name)
    assert obj is getattr(importlib.import_module(module, "ffr_jax"), attribute)
    assert instead


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        fj.no_such_name


def test_simulate_has_one_call_form():
    parameters = list(inspect.signature(fj.simulate).parameters)
    assert parameters[:2] == ["target", "x"]
    with pytest.raises(ValueError, match="must be a ffr_jax.Problem or a case"):
        fj.simulate("not a problem")
    case = fj.cases.slider_crank(4, 2, 2, 0.05)
    with pytest.raises(ValueError, match=r"give the case's design x"):
        fj.simulate(case)
    with pytest.raises(ValueError, match="take only keyword options"):
        fj.simulate(case, case.initial_design(0.5), 1e-8)


def test_importing_the_package_installs_no_log_filter():
    # The filter of jax's callback logger is attached by the first public call, not by the import
    # (a fresh interpreter: this process has called the package already).
    import subprocess
    import sys

    program = ("import logging, ffr_jax; "
               "print(any(type(f).__module__.startswith('ffr_jax') for f in logging.getLogger('jax._src.callback').filters))")
    out = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["False"], out.stderr[-2000:]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        importlib.reload(importlib.import_module("ffr_jax._dynamics._xla_flags"))
