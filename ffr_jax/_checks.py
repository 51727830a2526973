"""Checks of the numbers a user gives the package, where they enter, with a message that says what to do.

Every function here runs on concrete Python or NumPy values (at construction, or at trace time
for static settings) and raises `ValueError` (`DesignError` for designs); none of them traces.
A traced value (a tolerance passed as a JAX array under `jax.jit`) is let through unchecked.
"""

import math
import numbers
import os
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import DesignError

# Relative tolerances of the ODE solves. At RTOL_MAX and above the step-size controller accepts steps
# with a local error of a percent or more, and nothing bounds the error of psi: on the 4 x 2
# slider-crank psi is off by 9e-6 at rtol 1e-2, 3e-4 at 0.1 and a factor 7,000 at 1
# (benchmarks/RESULTS.md, "Bad input", second table); the small case of issue 17 gave psi = 1.4e101 at
# rtol = 1. Below RTOL_MIN (about 45 float64 machine epsilons) the error estimate of a step is
# round-off noise, so steps are rejected at random until the step budget runs out.
RTOL_MIN = 1e-14
RTOL_MAX = 1e-2


def float64_on(where: str) -> None:
    """float64 is on (`jax_enable_x64`), or a `ValueError` that says how to turn it back on.

    `import ffr_jax` turns it on; a user who turns it off afterwards (or calls inside
    `jax.experimental.disable_x64()`) would otherwise get an error from deep inside a traced
    program (`lax.add requires arguments to have the same dtypes`, issue 32).
    """
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:
        raise ValueError(
            f"{where}: ffr_jax computes in float64, but JAX's float64 mode (jax_enable_x64) is off: it was turned "
            "off after `import ffr_jax`, which turns it on. Turn it back on with "
            "jax.config.update('jax_enable_x64', True) (or leave the jax.experimental.disable_x64() block) "
            "before calling ffr_jax."
        )


def is_traced(value) -> bool:
    """Whether `value` is (or holds) a JAX tracer: its value is not known yet."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value))


def number(value, name: str) -> float:
    """`value` as a finite Python float, or a `ValueError` naming `name`."""
    if isinstance(value, bool) or isinstance(value, complex) or np.iscomplexobj(value):
        raise ValueError(f"{name} must be a real number, got {value!r}.")
    try:
        result = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}.") from None
    if not math.isfinite(result):
        raise ValueError(f"{name} must be finite, got {result}.")
    return result


def positive(value, name: str, advice: str = "") -> float:
    """A finite number `> 0`."""
    result = number(value, name)
    if not result > 0.0:
        raise ValueError(f"{name} must be positive, got {result}.{' ' + advice if advice else ''}")
    return result


def in_interval(value, name: str, low: float, high: float, *, low_open: bool = False, high_open: bool = False,
                advice: str = "") -> float:
    """A finite number in the interval from `low` to `high` (open or closed at each end)."""
    result = number(value, name)
    above = result > low if low_open else result >= low
    below = result < high if high_open else result <= high
    if not (above and below):
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        raise ValueError(f"{name} must lie in {interval}, got {result:g}.{' ' + advice if advice else ''}")
    return result


def integer(value, name: str, minimum: int = 1, advice: str = "") -> int:
    """A Python or NumPy integer `>= minimum` (not a bool, not a float such as `3.0`)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r} ({type(value).__name__})."
                         f"{' ' + advice if advice else ''}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value}.{' ' + advice if advice else ''}")
    return int(value)


def optional_integer(value, name: str, minimum: int = 1) -> int | None:
    """`None`, or an integer `>= minimum`."""
    return None if value is None else integer(value, name, minimum)


def tolerances(rtol, atol, where: str) -> None:
    """Relative and absolute tolerances of an ODE solve: `rtol` in `[RTOL_MIN, RTOL_MAX)`, `atol > 0`.

    `atol` has no upper bound: its unit is that of the state (positions in m, modal coordinates,
    `psi`), which only the user knows. It must be positive: the elastic coordinates and `psi` start
    at zero, where a purely relative error control (`atol = 0`) rejects every step.
    """
    if not is_traced(rtol):
        rtol = positive(rtol, f"rtol of {where}", "Useful values are 1e-6 (a quick look) to 1e-12 (reference "
                        "values); the default is 1e-10.")
        if not RTOL_MIN <= rtol < RTOL_MAX:
            raise ValueError(
                f"rtol of {where} must lie in [{RTOL_MIN:g}, {RTOL_MAX:g}), got {rtol:g}: "
                + ("a step may then carry an error of a percent or more, and psi and its gradient are "
                   "meaningless." if rtol >= RTOL_MAX else
                   "below that the solver's error estimate is round-off noise and the step budget runs out.")
                + " Useful values are 1e-6 (a quick look) to 1e-12 (reference values); the default is 1e-10."
            )
    if not is_traced(atol):
        positive(atol, f"atol of {where}", "Give an absolute tolerance well below the size of the elastic "
                 "coordinates and of psi (the default is 1e-12 forward, 1e-10 backward).")


def max_steps(value, where: str) -> int:
    """A step budget: an integer `>= 1`."""
    return integer(value, f"max_steps of {where}", 1, "It is the solver's step budget (default 1,000,000 forward, "
                   "200,000 for gradients); raise it for long horizons.")


def design_array(x, of_body: str = "") -> jnp.ndarray:
    """`x` as a float64 array: integers and float32 are converted, complex numbers are refused.

    `of_body` (e.g. `" for body 'rod'"`) names the body in the messages."""
    if is_traced(x):
        dtype = x.dtype
    else:
        x = np.asarray(x) if not isinstance(x, jax.Array) else _uncommitted(x)
        dtype = x.dtype
    if jnp.issubdtype(dtype, jnp.complexfloating):
        raise DesignError(f"The design vector{of_body} is complex ({dtype}); densities are real numbers in [x_min, 1]. "
                          "Pass x.real if the imaginary part is meant to be zero.")
    if not (jnp.issubdtype(dtype, jnp.floating) or jnp.issubdtype(dtype, jnp.integer) or dtype == jnp.bool_):
        raise DesignError(f"The design vector{of_body} must hold real numbers, got dtype {dtype}.")
    return jnp.asarray(x, dtype=jnp.float64)


def _uncommitted(x):
    """`x`, or an uncommitted copy of it where it is committed to the device an uncommitted array goes to.

    A committed array (`jax.device_put(x, device)`) is placed by its sharding, which is part of the key
    of every compiled program's cache: the same design committed to the default device recompiled the
    whole gradient (57 s on the reference case, issue 32). A design is small, so the copy through the
    host costs nothing next to a compilation. An array on another device, or split across devices,
    stays as it is: there the program must run where the data are.
    """
    if is_traced(x) or not getattr(x, "committed", False) or len(x.devices()) != 1:
        return x
    plain = jnp.asarray(np.asarray(x))
    return plain if plain.devices() == x.devices() else x


# Round-off slack at the design bounds: filtered densities are convex combinations whose weights sum to
# 1 up to n eps (n ~ 10^2 neighbours: ~1e-14), so a design at its bound x_min or 1 filters to a few eps
# outside it; 1e-12 admits that and nothing a user would mean (float32 rounding of 0.01 is 2e-10).
DESIGN_SLACK = 1e-12


def design_values(x, x_min: float, of_body: str = "") -> None:
    """Concrete design values: finite and inside `[x_min, 1]`, or a [`DesignError`][] naming the entries."""
    values = np.asarray(x)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise DesignError(f"Design vector contains NaN or inf{of_body} at {_entries(bad, values)}; every density must be "
                          f"a finite number in [x_min, 1] = [{x_min}, 1].")
    bad = np.flatnonzero((values < x_min - DESIGN_SLACK) | (values > 1.0 + DESIGN_SLACK))
    if bad.size:
        raise DesignError(f"Design densities must lie in [x_min, 1] = [{x_min}, 1]{of_body}; {_entries(bad, values)} "
                          f"{'is' if bad.size == 1 else 'are'} outside. Clip or project the design first "
                          f"(e.g. jnp.clip(x, {x_min}, 1)).{_rounding_hint(values[bad], x_min)}")


def _rounding_hint(outside: np.ndarray, x_min: float) -> str:
    """A hint when the densities outside lie within float32 rounding of a bound (a float32 design
    clipped to `[x_min, 1]` holds `float32(0.01) = 0.0099999998 < 0.01`)."""
    near = np.abs(outside - x_min) <= 1e-7 * x_min
    if not np.any(near):
        return ""
    return (" They lie within float32 rounding of x_min: build the design in float64 (jnp.float64) or clip it "
            "after converting, x = jnp.clip(jnp.asarray(x, jnp.float64), x_min, 1).")


def _entries(index: np.ndarray, values: np.ndarray) -> str:
    shown = ", ".join(f"x[{i}] = {float(values[i])!r}" for i in index[:3])
    more = f" and {index.size - 3} more" if index.size > 3 else ""
    return f"{'entry' if index.size == 1 else 'entries'} {shown}{more}"


def output_file(path, option: str) -> Path:
    """A file the caller will write: its directory exists and it is not itself a directory."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{option} {path} is a directory; give a file name (e.g. {path / 'out'}).")
    parent = path.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise ValueError(f"{option} {path}: the directory {parent} {what}; create it first or choose another path.")
    _writable(parent, option, path)
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(f"{option} {path}: the file exists and cannot be written; choose another path.")
    return path


def _writable(directory: Path, option: str, path: Path) -> None:
    """Whether a file can be created in `directory`, by creating (and removing) one: `os.access` says yes on a
    read-only file system for root, and for directories such as /sys. A `ValueError` before anything is
    computed, instead of an `OSError` after (issue 32: `--json` onto a read-only file system)."""
    try:
        with tempfile.NamedTemporaryFile(dir=directory, prefix=".ffr-jax-write-check-"):
            pass
    except OSError as err:
        raise ValueError(f"{option} {path}: cannot create a file in {directory} ({err.strerror or err}); "
                         "choose a directory you can write to.") from None


def output_directory(path, option: str) -> Path:
    """A directory the caller will create or write into: not an existing file, and creatable."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{option} {path} is a file, not a directory; choose a directory name.")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{option} {path}: {parent} is a file, so the directory cannot be created.")
            break
    return path
