"""The "Bad input" table of benchmarks/RESULTS.md (issue 17): every row of `tests/bad_input_cases.py`
(API calls and `ffr-jax` command lines on one small slider-crank), where it is caught, the message,
and the time to fail.

Each row is run twice in one process: the first time (which pays for any compilation the row needs;
rows run in table order, so a compiled program is paid for by its first row) and again. CLI rows run
`ffr_jax._app._cli.main` in this process; one extra row times the real entry point in a subprocess (Python
start and JAX import included). A row that does not raise its error, or whose message carries a
traceback or XLA's wrapper, is marked FAIL (the script then exits 1).

    PYTHONPATH=$PWD python benchmarks/bench_bad_input.py [--out benchmarks/results/bad_input.md]
"""

import argparse
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).parent.parent / "tests"))
import jax  # noqa: E402

import bad_input_cases as bic  # noqa: E402

FOREIGN = ("Traceback", "INTERNAL:", "CpuCallback", "EquinoxRuntimeError", "jaxlib", "scipy")


def _short(text: str, n: int = 150) -> str:
    text = " ".join(text.split())
    text = text.replace("|", "\\|")
    return text if len(text) <= n else text[: n - 1] + "…"


def api_row(ctx, bad):
    with bic.user_view():
        seconds, err, _ = bic.timed(lambda: jax.block_until_ready(bad.call(ctx)))
        again, _, _ = bic.timed(lambda: jax.block_until_ready(bad.call(ctx)))
    ok = (err is not None and isinstance(err, bad.error) and re.search(bad.match, str(err)) is not None
          and not any(w in str(err) for w in FOREIGN))
    message = "(no error)" if err is None else f"{type(err).__name__}: {err}"
    return ok, seconds, again, message


def cli_row(ctx, bad):
    start = time.perf_counter()
    status, _, err = bic.run_cli(ctx, bad)
    seconds = time.perf_counter() - start
    start = time.perf_counter()
    bic.run_cli(ctx, bad)
    again = time.perf_counter() - start
    line = err.strip().splitlines()[-1] if err.strip() else ""
    ok = status == 2 and re.search(bad.match, line) is not None and not any(w in err for w in FOREIGN)
    return ok, seconds, again, f"exit {status}: {line}"


def subprocess_row(tmp):
    path = pathlib.Path(tmp) / "missing" / "psi.json"
    env = dict(os.environ, PYTHONPATH=str(pathlib.Path(__file__).resolve().parent.parent))
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", "import sys; from ffr_jax._app._cli import main; sys.exit(main())",
                             "gradient", "slider-crank", "--json", str(path)], capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - start
    line = result.stderr.strip().splitlines()[-1] if result.stderr.strip() else ""
    ok = result.returncode == 2 and "does not exist" in line and "Traceback" not in result.stderr
    return ok, seconds, float("nan"), f"exit {result.returncode}: {line}"


def rtol_rows(ctx):
    """psi of the small case against the forward rtol, bypassing the entry check (the evidence for
    `_checks.RTOL_MAX`): one compiled program, rtol passed as an array."""
    import jax.numpy as jnp

    from ffr_jax._api import _simulate_case

    rows = []
    for rtol in (1.0, 0.1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12):
        seconds, err, out = bic.timed(lambda: float(_simulate_case(ctx.case, ctx.x, None, jnp.asarray(rtol), 1e-12, None,
                                                                   False, 1_000_000, None).psi))
        rows.append((rtol, out, None if err is None else f"{type(err).__name__}: {str(err)[:80]}", seconds))
    reference = rows[-1][1]
    lines = ["", f"psi of the small case (x = 0.5, atol 1e-12) against the forward rtol, the entry check bypassed "
             f"(`_simulate_case` with rtol as an array; one compilation, paid by the first row); reference: rtol 1e-12, "
             f"psi = {reference:.10e}.", "",
             "| rtol | psi | relative error | accepted by the check | time (s) |", "|---:|---:|---:|---|---:|"]
    from ffr_jax._checks import RTOL_MAX, RTOL_MIN

    for rtol, psi, err, seconds in rows:
        value = err if psi is None else f"{psi:.6e}"
        rel = "–" if psi is None else f"{abs(psi - reference) / abs(reference):.1e}"
        lines.append(f"| {rtol:g} | {value} | {rel} | {'yes' if RTOL_MIN <= rtol < RTOL_MAX else 'no'} | {seconds:.2f} |")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=None, help="also write the table to this file")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        ctx = bic.Ctx(pathlib.Path(tmp))
        setup_s = time.perf_counter() - start
        rows = [("API", b.name, b.where, *api_row(ctx, b)) for b in bic.API]
        rows += [("CLI", f"`ffr-jax {b.argv.split(' ', 1)[0]} … {b.name}`", b.where, *cli_row(ctx, b)) for b in bic.CLI]
        rtol_table = rtol_rows(ctx)
        rows.append(("CLI (subprocess)", "`ffr-jax gradient slider-crank --json missing/psi.json`", "CLI output paths",
                     *subprocess_row(tmp)))
    lines = [
        f"Small case {bic.SMALL} built in {setup_s:.1f} s (not in the times below).",
        "",
        "| | input | caught in | message (start) | time to fail, first (s) | again (s) | ok |",
        "|---|---|---|---|---:|---:|---|",
    ]
    failed = 0
    for kind, name, where, ok, first, again, message in rows:
        failed += not ok
        lines.append(f"| {kind} | {name} | {where} | {_short(message)} | {first:.3f} | {again:.3f} | "
                     f"{'ok' if ok else 'FAIL'} |")
    lines.append("")
    lines.append(f"{len(rows)} rows, {failed} failed.")
    lines += rtol_table
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
