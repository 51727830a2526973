"""The per-iteration record of an optimisation run."""

from typing import NamedTuple

import numpy as np


class History(NamedTuple):
    """Per-iteration values, one entry per completed step `k = 0, 1, ...`.

    - `value`: `psi(x_k)`; `volume`: volume fraction of `x_{k+1}` (NaN when the run has no
      [`VolumeConstraint`][]); `change`: `max |x_{k+1} - x_k|`.
    - `constraints`: `(steps, m)` the normalised values `g_i(x_k)` of the inequality constraints
      an optimizer such as [`MMA`][] takes (`None` or `(steps, 0)` for none); `names`: their `m`
      labels.
    """

    value: np.ndarray
    volume: np.ndarray
    change: np.ndarray
    constraints: np.ndarray | None = None
    names: tuple[str, ...] = ()

    @classmethod
    def empty(cls, names: tuple[str, ...] = ()) -> "History":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, len(names))), tuple(names))

    @property
    def constraint_values(self) -> np.ndarray:
        """`(steps, m)` the `g_i(x_k)` (an empty `(steps, 0)` array when there are none)."""
        if self.constraints is None:
            return np.zeros((self.steps, 0))
        return np.asarray(self.constraints).reshape(self.steps, len(self.names))

    def append(self, value: float, volume: float, change: float, constraints=()) -> "History":
        """A new history with one more entry (`constraints`: the `m` values `g_i(x_k)`)."""
        row = np.asarray(constraints, dtype=float).reshape(1, len(self.names))
        return History(
            np.append(self.value, value), np.append(self.volume, volume), np.append(self.change, change),
            np.concatenate([self.constraint_values, row]), self.names,
        )

    @property
    def steps(self) -> int:
        """The number of recorded steps."""
        return len(self.value)
