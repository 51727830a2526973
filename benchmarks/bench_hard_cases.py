"""The hard-case table (issue 6): each hard member of the slider–crank family, the adjoint gradient
against finite differences, the agreement and the time — the slow members included.

The cases and checks are those of `tests/test_hard_cases.py` (defined once in `tests/hard_cases.py`):
the adjoint gradient (forward rtol 1e-10, backward 1e-8) against fourth-order central differences
of `psi` at rtol 1e-12 with a step of 1e-4 (a random direction and the largest entry, or every
entry; one-sided at `x_min`); agreement = max |adjoint - fd| / max |grad|. Cases where the
mechanism cannot be simulated must end in a clear error; the table records which.

```
flock /tmp/ffr_bench.lock python benchmarks/bench_hard_cases.py
flock /tmp/ffr_bench.lock python benchmarks/bench_hard_cases.py --skip "long horizon"
```
Writes `benchmarks/results/hard_cases.md` and the "Hard cases" section of `benchmarks/RESULTS.md`.
"""

import argparse
import pathlib
import sys
import time

import jax
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent.parent / "tests"))
import hard_cases as hc  # noqa: E402

import ffr_jax  # noqa: E402

RESULTS = pathlib.Path(__file__).parent / "results"
SECTION = "## Hard cases (bench_hard_cases.py)"
BASE = dict(nx=12, ny=2, n_modes=4, t1=0.15, t_ramp=0.05)


def slider_crank(**changes):
    a = {**BASE, **changes}
    return ffr_jax.cases.slider_crank(a.pop("nx"), a.pop("ny"), a.pop("n_modes"), a.pop("t1"), **a)


def stiff_adjoint_value_and_grad(case, x):
    """The adjoint with the stiff route: Rodas5P forward (rtol 1e-10) and backward (the adjoint's 1e-8)."""
    return ffr_jax.value_and_grad(case, x, "adjoint", solver=ffr_jax.Rodas5P())


def gradient_row(case, x, value_and_grad=None, **check_options):
    value_and_grad = hc.adjoint_value_and_grad if value_and_grad is None else value_and_grad
    start = time.perf_counter()
    psi, grad = jax.block_until_ready(value_and_grad(case, x))
    first = time.perf_counter() - start
    run = float("nan")
    if first < 120:  # a second, compiled run only where it is cheap; else first ~ compile + run
        start = time.perf_counter()
        jax.block_until_ready(value_and_grad(case, x))
        run = time.perf_counter() - start
    grad = np.asarray(grad)
    start = time.perf_counter()
    checks = hc.gradient_checks(case, x, grad, **check_options)
    fd = time.perf_counter() - start
    finite = bool(np.all(np.isfinite(grad)) and np.isfinite(float(psi)))
    return {"psi": float(psi), "finite": finite, "agreement": hc.agreement(grad, checks),
            "compared": f"adjoint vs fd ({len(checks)} checks: " + ", ".join(c[0] for c in checks) + ")",
            "first_s": first, "run_s": run, "fd_s": fd}


def error_row(call, expected: str):
    start = time.perf_counter()
    try:
        jax.block_until_ready(call())
    except Exception as err:  # the outcome under test is the error itself
        message = str(err)
        found = [m for m in expected.split("|") if m in message]
        if found:
            outcome = f"{type(err).__name__}: '{found[0]}'"
        else:  # name the error: its first line that is not traceback noise
            lines = [ln.strip() for ln in message.splitlines() if ln.strip() and not ln.startswith(" ")]
            summary = next((ln for ln in lines if type(err).__name__ in ln), lines[0] if lines else "")
            outcome = f"unexpected {type(err).__name__}: {summary[:200]}"
        return {"outcome": outcome, "ok": bool(found), "first_s": time.perf_counter() - start}
    return {"outcome": "returned a number (expected an error)", "ok": False, "first_s": time.perf_counter() - start}


def cases():
    base = slider_crank()
    x05 = base.initial_design(0.5)
    yield "crossing retained eigenvalues", "12x2, 4 modes, t1 0.15", lambda: gradient_row(base, hc.crossing_design(base)[0])
    yield "void regions at x_min", "12x2, 4 modes, t1 0.15", lambda: gradient_row(base, hc.void_design(base))
    f1 = float(base.frequencies(x05)[0])
    yield ("crank speed at 1st resonance", f"12x2, speed 2 pi {f1:.1f} Hz",
           lambda: gradient_row(hc.variant(base, slider_crank(speed=2 * np.pi * f1)), x05))
    yield ("near dead point eps/l = 0.98", "12x2, 4 modes, t1 0.15",
           lambda: gradient_row(hc.variant(base, slider_crank(eccentricity=0.98)), x05))
    yield ("dead point reached, eps/l = 0.99", "12x2, 4 modes, t1 0.15",
           lambda: error_row(lambda: hc.adjoint_value_and_grad(hc.variant(base, slider_crank(eccentricity=0.99)), x05),
                             "partition became singular|did not converge"))
    yield ("dead point, eps/l = 1", "factory", lambda: error_row(lambda: slider_crank(eccentricity=1.0),
                                                                 "eccentricity must lie in (0, l)"))
    coarse = slider_crank(nx=4, n_modes=3, t1=0.4, t_ramp=0.1)
    yield ("very coarse mesh", "4x2 (4 variables), 3 modes, t1 0.4",
           lambda: gradient_row(coarse, coarse.initial_design(0.5) + np.array([0.1, -0.1, 0.2, -0.2]),
                                n_directions=0, n_entries=coarse.n_design))
    # 20 modes with the default explicit route (Dopri8); 30 modes with the stiff route (Rodas5P
    # forward and backward, issue 15): with Dopri8 its adjoint gradient took over half an hour.
    for n_modes in (20,):
        many = slider_crank(n_modes=n_modes)
        yield (f"{n_modes} retained modes (stiff)", f"12x2, t1 0.15",
               lambda many=many: gradient_row(many, many.initial_design(0.5)))
    many30 = slider_crank(n_modes=30)
    yield ("30 retained modes, stiff route (Rodas5P)", "12x2, t1 0.15",
           lambda: gradient_row(many30, many30.initial_design(0.5), stiff_adjoint_value_and_grad))
    fine = slider_crank(nx=48, ny=4, n_modes=6)
    yield "fine mesh, voids", "48x4 (184 variables), 6 modes, t1 0.15", lambda: gradient_row(fine, hc.void_design(fine))
    long = slider_crank(nx=4, n_modes=2, t1=30.0, t_ramp=2.0)
    yield ("long horizon t1 = 30 s", "4x2, 2 modes, ramp 2 s",
           lambda: gradient_row(long, long.initial_design(0.5), n_directions=0, n_entries=1))


def markdown(rows, command):
    lines = [SECTION, "", f"Command: `{command}`", "",
             "Adjoint gradient (rtol 1e-10 forward, 1e-8 backward) against fourth-order central differences "
             "of psi at rtol 1e-12, step 1e-4 (one-sided at x_min). Agreement = max |adjoint - fd| / max |grad| "
             "over the checks. Times on a shared 2-core machine: first call (compile + run), a second run "
             "(skipped, nan, where the first took over 2 min), "
             "and the finite-difference checks. Cases of the 12x2/4-mode structure share one compilation "
             "(the first row pays it).", "",
             "| case | setting | methods compared | finite | agreement | outcome | first call [s] | run [s] | fd checks [s] |",
             "|---|---|---|---|---:|---|---:|---:|---:|"]
    for name, setting, r in rows:
        if "error" in r:
            lines.append(f"| {name} | {setting} | – | – | – | FAILED: {r['error']} | | | |")
        elif "outcome" in r:
            lines.append(f"| {name} | {setting} | expects a clear error | – | – | "
                         f"{'OK' if r['ok'] else 'WRONG'}: {r['outcome']} | {r['first_s']:.1f} | | |")
        else:
            lines.append(f"| {name} | {setting} | {r['compared']} | {r['finite']} | {r['agreement']:.1e} | "
                         f"{'OK' if r['finite'] and r['agreement'] < 1e-6 else 'CHECK'} | {r['first_s']:.1f} | "
                         f"{r['run_s']:.2f} | {r['fd_s']:.1f} |")
    return "\n".join(lines) + "\n"


def write_section(text: str):
    """Rewrite this script's section of RESULTS.md (`_results.write_section`), leaving the others as they are."""
    from _results import write_section as write

    write(SECTION.removeprefix("## "), text.removeprefix(SECTION))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skip", nargs="*", default=[], help="skip cases whose name contains one of these")
    parser.add_argument("--only", nargs="*", default=None,
                        help="run only cases whose name contains one of these (rows printed and written to "
                             "results/hard_cases_only.md; RESULTS.md is left as it is)")
    args = parser.parse_args()
    command = "flock /tmp/ffr_bench.lock python benchmarks/bench_hard_cases.py " + " ".join(
        f'--skip "{s}"' for s in args.skip)
    rows = []
    for name, setting, run in cases():
        if any(s in name for s in args.skip) or (args.only is not None and not any(s in name for s in args.only)):
            continue
        try:
            r = run()
        except Exception as err:  # a failing row is reported in the table, the others still run
            r = {"error": f"{type(err).__name__}: {str(err).splitlines()[0][:200]}"}
        rows.append((name, setting, r))
        print(name, setting, r, flush=True)
    RESULTS.mkdir(exist_ok=True)
    if args.only is not None:
        command += " --only " + " ".join(f'"{s}"' for s in args.only)
        text = markdown(rows, command.strip())
        (RESULTS / "hard_cases_only.md").write_text(text)
        print(text)
        return
    text = markdown(rows, command.strip())
    (RESULTS / "hard_cases.md").write_text(text)
    write_section(text)
    print(text)


if __name__ == "__main__":
    main()
