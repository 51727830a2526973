"""Progress of a run through tqdm: a live bar on a terminal, a plain line every tenth of the run otherwise."""

import sys
import time

from tqdm.auto import tqdm


class Progress:
    """Report completed steps of a run on standard error.

    On a terminal a `tqdm` bar with the last step's numbers as its postfix; when standard error is
    not a terminal (a log file, CI), carriage returns would pile up, so the same text as the bar
    (`tqdm.format_meter`) is written as one line at every tenth of the run and at its end.

    **Arguments:**
    - `total`: planned steps; `initial`: steps done before (a resumed run); `enabled`: report at all.
    """

    def __init__(self, total: int, initial: int, enabled: bool):
        self.total, self.initial, self.enabled = total, initial, enabled
        self.tty = enabled and sys.stderr.isatty()
        self.start = time.perf_counter()
        self.bar = tqdm(total=total, initial=initial, file=sys.stderr, unit="step", dynamic_ncols=True,
                        disable=not self.tty, leave=True)

    def compiling(self) -> None:
        """Say, before the first step of a run, that it compiles (the first step of a process takes
        from seconds to minutes, all of it tracing and compiling; later steps reuse the program)."""
        if not self.enabled:
            return
        if self.tty:
            self.bar.set_postfix_str("compiling the step (first call)...", refresh=True)
            return
        sys.stderr.write(f"step {self.initial + 1}/{self.total}: compiling the step (first call)...\n")
        sys.stderr.flush()

    def update(self, done: int, postfix: str) -> None:
        """Record that `done` steps are complete; `postfix`: the last step's numbers."""
        if not self.enabled:
            return
        if self.tty:
            self.bar.set_postfix_str(postfix, refresh=False)
            self.bar.update(1)
            return
        if done == self.total or done % max(1, self.total // 10) == 0:
            line = tqdm.format_meter(done, self.total, time.perf_counter() - self.start, unit="step",
                                     initial=self.initial, postfix=postfix, ncols=120)
            sys.stderr.write(line + "\n")
            sys.stderr.flush()

    def close(self) -> None:
        self.bar.close()
