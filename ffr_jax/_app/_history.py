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
    - `grey`: the [`grey_share`][] of `x_{k+1}` (share of elements with `0.1 < x_phys < 0.9` of the
      physical densities the volume constraint measures; NaN without a [`VolumeConstraint`][], and for
      steps recorded before the share was kept); `None` in a history made without it.
    """

    value: np.ndarray
    volume: np.ndarray
    change: np.ndarray
    constraints: np.ndarray | None = None
    names: tuple[str, ...] = ()
    grey: np.ndarray | None = None

    @classmethod
    def empty(cls, names: tuple[str, ...] = ()) -> "History":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, len(names))), tuple(names), np.zeros(0))

    @property
    def grey_values(self) -> np.ndarray:
        """`(steps,)` the grey shares (NaN where none was recorded)."""
        return np.full(self.steps, np.nan) if self.grey is None else np.asarray(self.grey, dtype=float)

    @property
    def constraint_values(self) -> np.ndarray:
        """`(steps, m)` the `g_i(x_k)` (an empty `(steps, 0)` array when there are none)."""
        if self.constraints is None:
            return np.zeros((self.steps, 0))
        return np.asarray(self.constraints).reshape(self.steps, len(self.names))

    def append(self, value: float, volume: float, change: float, constraints=(), grey: float = float("nan")
               ) -> "History":
        """A new history with one more entry (`constraints`: the `m` values `g_i(x_k)`; `grey`: the grey
        share of `x_{k+1}`)."""
        row = np.asarray(constraints, dtype=float).reshape(1, len(self.names))
        return History(
            np.append(self.value, value), np.append(self.volume, volume), np.append(self.change, change),
            np.concatenate([self.constraint_values, row]), self.names, np.append(self.grey_values, grey),
        )

    def drop_last(self) -> "History":
        """The history without its last entry."""
        return History(self.value[:-1], self.volume[:-1], self.change[:-1], self.constraint_values[:-1], self.names,
                       self.grey_values[:-1])

    @property
    def steps(self) -> int:
        """The number of recorded steps."""
        return len(self.value)
