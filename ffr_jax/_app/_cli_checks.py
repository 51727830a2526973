"""Checks of the `ffr-jax` command-line options, run before anything is computed.

Each raises `ValueError` with the option's name; the CLI prints it as `ffr-jax: error: ...` and
exits with status 2. The same checks as the library's ([`_checks`][]), so that a bad option never
costs a compilation.
"""

import math
from pathlib import Path
from types import SimpleNamespace

from .. import _checks

# The CLI builds the paper's slider-crank with the default SIMP law (REFERENCE_CASE §1).
X_MIN = 0.01


def case_options(args) -> None:
    """`--nx`, `--ny`, `--modes`, `--t1` (and `--value` where the command has it)."""
    for option in ("nx", "ny", "modes"):
        if getattr(args, option, None) is not None:
            _checks.integer(getattr(args, option), f"--{option}", 1)
    if getattr(args, "t1", None) is not None:
        _checks.positive(args.t1, "--t1", "It is the end time in s.")
    if getattr(args, "value", None) is not None:
        _checks.in_interval(args.value, "--value", X_MIN, 1.0, advice="It is the uniform design density.")


def gradient_options(args) -> None:
    """The options of `ffr-jax gradient`, and its output paths."""
    case_options(args)
    _checks.tolerances(args.rtol, args.atol, "the forward solve (--rtol, --atol)")
    if args.backward_rtol is not None or args.backward_atol is not None:
        if args.method not in ("adjoint", "backsolve"):
            raise ValueError(f"--backward-rtol/--backward-atol apply to --method adjoint or backsolve, not {args.method}.")
        _checks.tolerances(1e-8 if args.backward_rtol is None else args.backward_rtol,
                           1e-10 if args.backward_atol is None else args.backward_atol,
                           "the backward solve (--backward-rtol, --backward-atol)")
    if args.fd_step is not None:
        if args.method != "fd":
            raise ValueError(f"--fd-step applies to --method fd, not {args.method}.")
        _checks.in_interval(args.fd_step, "--fd-step", 0.0, (1.0 - X_MIN) / 2, low_open=True, high_open=True,
                            advice="It is the finite-difference step h (about 1e-4 to 1e-6).")
    _checks.max_steps(args.max_steps, "the CLI (--max-steps)")
    if not args.repeat >= 1:
        raise ValueError(f"--repeat is the number of timed calls, at least 1, got {args.repeat}.")
    if args.json is not None:
        _checks.output_file(args.json, "--json")
    if args.plot is not None:
        _checks.output_file(args.plot, "--plot")
        _plot_format(args.plot)


def _plot_format(path) -> None:
    import matplotlib.figure

    formats = matplotlib.figure.Figure().canvas.get_supported_filetypes()
    suffix = Path(path).suffix.lstrip(".").lower()
    if suffix not in formats:
        raise ValueError(f"--plot {path}: unknown image format {suffix!r}; use one of "
                         f"{', '.join(sorted(formats))} (e.g. grad.png).")


def optimize_options(settings: dict, args, directory: Path, resume: bool) -> None:
    """The settings of `ffr-jax optimize` (defaults, a resumed checkpoint's, the options) and its directory."""
    case_options(SimpleNamespace(**{k: settings.get(k) for k in ("nx", "ny", "modes", "t1")}))
    _checks.tolerances(settings["rtol"], settings["atol"], "the solves (--rtol, --atol)")
    _checks.in_interval(settings["volume"], "--volume", X_MIN, 1.0, low_open=True,
                        advice="It is the volume fraction V of the design.")
    _checks.positive(settings["lr"], "--lr", "It is Adam's learning rate (default 0.02).")
    _checks.in_interval(settings["move"], "--move", 0.0, 1.0, low_open=True, advice="It is the OC move limit.")
    _checks.number(settings["filter_radius"], "--filter-radius")
    if settings["filter_radius"] < 0:
        raise ValueError(f"--filter-radius must be >= 0 (0 = no filter), got {settings['filter_radius']}.")
    _checks.number(settings["beta"], "--projection-beta")
    if settings["beta"] < 0:
        raise ValueError(f"--projection-beta must be >= 0 (0 = no projection), got {settings['beta']}.")
    if settings["beta"] > 0:
        _checks.positive(settings["beta_max"], "--beta-max")
        _checks.integer(settings["beta_every"], "--beta-every", 1)
        _checks.in_interval(settings["eta"], "--projection-eta", 0.0, 1.0, low_open=True, high_open=True)
    robust_options(settings)
    _checks.integer(args.iters, "--iters", 0)
    _checks.integer(args.checkpoint_every, "--checkpoint-every", 1)
    _checks.output_directory(directory, "--resume" if resume else "--out")
    if resume:
        from ._checkpoint import load_checkpoint

        load_checkpoint(directory / "checkpoint.npz", design_bounds=(X_MIN, 1.0))
    if not resume and (directory / "checkpoint.npz").exists():
        raise ValueError(f"--out {directory} already holds a run (checkpoint.npz); continue it with --resume "
                         f"{directory}, or choose another directory.")


def robust_options(settings: dict) -> tuple | None:
    """`(eta_eroded, eta_dilated, objective)` of the robust projection that `--eta-eroded`, `--eta-dilated` and
    `--robust-objective` ask for, or `None` (the plain projection), checked by `fj.HeavisideProjection`'s own
    rule (its message, after the options as given), so that the shell and Python refuse the same thresholds."""
    from .._optimize._projection import HeavisideProjection

    eroded, dilated = settings.get("eta_eroded"), settings.get("eta_dilated")
    objective = settings.get("robust_objective", "max")
    if eroded is None and dilated is None and objective == "max":
        return None
    given = " ".join(f"--{key.replace('_', '-')} {settings.get(key)}"
                     for key in ("eta_eroded", "eta_dilated", "robust_objective")
                     if settings.get(key) not in (None, "max"))
    try:
        for value, option in ((eroded, "--eta-eroded"), (dilated, "--eta-dilated")):
            if value is not None:
                _checks.number(value, option)
        HeavisideProjection(settings["eta"], x_min=X_MIN, eta_eroded=eroded, eta_dilated=dilated, objective=objective)
    except ValueError as err:
        raise ValueError(f"{given}: {err}") from None
    return float(eroded), float(dilated), objective


def finite_record(record: dict, where: str) -> dict:
    """`record` for strict JSON: a `ValueError` naming the first non-finite number (JSON has no NaN or inf)."""

    def visit(value, path):
        if isinstance(value, dict):
            for key, item in value.items():
                visit(item, f"{path}.{key}" if path else key)
        elif isinstance(value, (list, tuple)):
            for i, item in enumerate(value):
                visit(item, f"{path}[{i}]")
        elif isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{where}: {path} is {value}; nothing was written (strict JSON has no NaN or inf).")

    visit(record, "")
    return record


def written(write, path, option: str) -> None:
    """`write(path)`, with a file-system error (a read-only file system, a full disk, a directory removed
    since the options were checked) as one `ValueError` naming the option and what was kept, instead of
    an `OSError` traceback after the computation (issue 32)."""
    try:
        write(path)
    except OSError as err:
        raise ValueError(f"{option} {path}: could not write the file ({err.strerror or err}); the results printed "
                         "above were computed but not saved. Choose a path you can write to and run again.") from None
