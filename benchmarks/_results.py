"""Write one section of benchmarks/RESULTS.md, leaving the other sections as they are.

RESULTS.md opens with a headline table and groups the scripts' sections by question: a `## <question>`
heading, under it each script's `### <title>`. A section starts at its heading line (`## <title>` or
`### <title>`) and runs to the next heading of the same or a higher level (outside code fences). Each
benchmark script owns its sections and rewrites them whole, so RESULTS.md always shows the latest run of
every script; a section that is not there yet is appended at the end as `## <title>`.
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


def _heading_levels(lines: list[str]) -> list[int]:
    """The Markdown heading level of each line (0: not a heading, or inside a code fence)."""
    levels, fenced = [], False
    for line in lines:
        if line.lstrip().startswith("```"):
            fenced = not fenced
        hashes = len(line) - len(line.lstrip("#"))
        levels.append(hashes if not fenced and 0 < hashes <= 6 and line[hashes:hashes + 1] == " " else 0)
    return levels


def write_section(title: str, body: str) -> None:
    """Replace (or append) the section `title` of RESULTS.md with `body`.

    Args:
        title: the heading text, without the `#` marks; found as `## title` or `### title`.
        body: the section's text below its heading, written for a `##` section: its own headings are
            moved down a level where the section is a `###` one.
    """
    text = RESULTS.read_text() if RESULTS.exists() else HEADER
    lines = text.splitlines(keepends=True)
    levels = _heading_levels(lines)
    start = next((i for i, line in enumerate(lines) if levels[i] in (2, 3) and line[levels[i] + 1:].rstrip() == title),
                 None)
    level = 2 if start is None else levels[start]
    body_lines = body.rstrip().splitlines(keepends=True)
    shift = "#" * (level - 2)
    body_lines = [shift + line if n else line for line, n in zip(body_lines, _heading_levels(body_lines))]
    new = ["#" * level + f" {title}\n\n", "".join(body_lines) + "\n\n"]
    if start is None:
        if lines and not lines[-1].endswith("\n"):
            lines[-1] += "\n"
        lines += ["\n"] + new
    else:
        end = next((i for i in range(start + 1, len(lines)) if 0 < levels[i] <= level), len(lines))
        lines[start:end] = new
    RESULTS.write_text("".join(lines).replace("\n\n\n", "\n\n"))
