"""A plain-text progress line (no dependency; the driver decides where it goes)."""


def progress_line(done: int, total: int, value: float, volume: float, change: float, seconds: float,
                  width: int = 24) -> str:
    """One line such as `[#########.......]  12/50  psi 1.234e-07  V 0.5000  change 3.1e-02  0.41 s/it`.

    **Arguments:**
    - `done`, `total`: completed and planned steps.
    - `value`, `volume`, `change`: the last step's [`StepInfo`][] as floats.
    - `seconds`: wall time of the last step.
    - `width`: characters of the bar.

    **Returns:** the line, without a line break.
    """
    filled = width if total <= 0 else min(width, (width * done) // total)
    digits = len(str(total))
    return (
        f"[{'#' * filled}{'.' * (width - filled)}] {done:>{digits}}/{total}  psi {value:.4e}  "
        f"V {volume:.4f}  change {change:.2e}  {seconds:.2f} s/it"
    )
