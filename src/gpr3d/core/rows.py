"""Rows appended to an array that grows as they come (live mode's traces and poses, the fusion filter's samples)."""

from __future__ import annotations

import numpy as np

__all__ = ["GrowingRows"]


class GrowingRows:
    """Rows of shape ``shape`` (``()``: scalars) appended at the end of an array that doubles when full: appending
    is amortised O(rows added), where concatenating onto an array copies every row each time. ``rows[key]``
    indexes the rows appended so far (a view, valid until the next append); ``len(rows)``, or ``rows.n``, counts
    them."""

    def __init__(self, *shape: int, dtype=float):
        self._a = np.zeros((64, *shape), dtype)
        self.n = 0

    def append(self, rows) -> None:
        """Append ``rows`` (one row, or an array of them)."""
        rows = np.asarray(rows, self._a.dtype).reshape(-1, *self._a.shape[1:])
        if self.n + len(rows) > len(self._a):
            grown = np.zeros((2 * (self.n + len(rows)), *self._a.shape[1:]), self._a.dtype)
            grown[: self.n] = self._a[: self.n]
            self._a = grown
        self._a[self.n: self.n + len(rows)] = rows
        self.n += len(rows)

    def __getitem__(self, key):
        return self._a[: self.n][key]

    def __len__(self) -> int:
        return self.n
