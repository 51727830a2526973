"""Write one section of benchmarks/RESULTS.md, leaving the other sections as they are.

A section starts at a line `## <title>` and runs to the next `## ` line. Each benchmark script owns
its sections and rewrites them whole, so RESULTS.md always shows the latest run of every script.
"""

import pathlib
import platform
import os

import jax

RESULTS = pathlib.Path(__file__).with_name("RESULTS.md")
HEADER = (
    "# Benchmark results\n\n"
    "Written by the scripts in this folder (see README.md); each section names the command that\n"
    "produced it. Timings: compile separate from run, medians of several runs, ratios from one run.\n"
)


def machine() -> str:
    """One line describing where the numbers were measured."""
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"{platform.machine()}, {os.cpu_count()} CPUs, jax {jax.__version__} on {jax.default_backend()}, "
            f"load average {load} (1/5/15 min)")


def timed(fn, *args, runs: int = 3):
    """`(median run time [s], output)` of `fn(*args)` over `runs` calls after one warm-up call (compilation)."""
    import statistics
    import time

    jax.block_until_ready(fn(*args))
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        samples.append(time.perf_counter() - start)
    return statistics.median(samples), out


def write_section(title: str, body: str) -> None:
    """Replace (or append) the section `## title` of RESULTS.md with `body`."""
    text = RESULTS.read_text() if RESULTS.exists() else HEADER
    lines = text.splitlines(keepends=True)
    head = f"## {title}"
    start = next((i for i, line in enumerate(lines) if line.rstrip() == head), None)
    new = [head + "\n\n", body.rstrip() + "\n\n"]
    if start is None:
        if lines and not lines[-1].endswith("\n"):
            lines[-1] += "\n"
        lines += ["\n"] + new
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        lines[start:end] = new
    RESULTS.write_text("".join(lines).replace("\n\n\n", "\n\n"))
