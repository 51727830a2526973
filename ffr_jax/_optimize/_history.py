"""The per-iteration record of an optimisation run."""

from typing import NamedTuple

import numpy as np


class History(NamedTuple):
    """Per-iteration values, one entry per completed step `k = 0, 1, ...`.

    - `value`: `psi(x_k)`; `volume`: volume fraction of `x_{k+1}`;
      `change`: `max |x_{k+1} - x_k|`.
    """

    value: np.ndarray
    volume: np.ndarray
    change: np.ndarray

    @classmethod
    def empty(cls) -> "History":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0))

    def append(self, value: float, volume: float, change: float) -> "History":
        """A new history with one more entry."""
        return History(
            np.append(self.value, value), np.append(self.volume, volume), np.append(self.change, change)
        )

    @property
    def steps(self) -> int:
        """The number of recorded steps."""
        return len(self.value)
