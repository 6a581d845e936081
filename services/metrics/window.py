"""Sliding-window statistics: pure, driven by the caller's clock."""

from __future__ import annotations

from collections import deque

import numpy as np


class Window:
    """(time, value) samples kept for ``span_s`` seconds of the caller's monotonic clock."""

    def __init__(self, span_s: float, maxlen: int = 100_000) -> None:
        self.span_s = span_s
        self._items: deque[tuple[float, float]] = deque(maxlen=maxlen)

    def add(self, t: float, value: float) -> None:
        self._items.append((t, value))

    def prune(self, now: float) -> None:
        while self._items and self._items[0][0] < now - self.span_s:
            self._items.popleft()

    def values(self, now: float) -> np.ndarray:
        self.prune(now)
        return np.fromiter((v for _, v in self._items), dtype=np.float64, count=len(self._items))

    def rate(self, now: float) -> float:
        """Samples per second over the window (0 with fewer than two samples)."""
        self.prune(now)
        if len(self._items) < 2:
            return 0.0
        elapsed = self._items[-1][0] - self._items[0][0]
        return (len(self._items) - 1) / elapsed if elapsed > 0 else 0.0


def percentiles(values: np.ndarray) -> dict[str, float]:
    """p50, p95, p99, mean and count of ``values`` (all zero when empty)."""
    if values.size == 0:
        return {"p50": 0.0, "p95": 0.0, "p99": 0.0, "mean": 0.0, "count": 0.0}
    p50, p95, p99 = np.percentile(values, [50, 95, 99])
    return {
        "p50": float(p50),
        "p95": float(p95),
        "p99": float(p99),
        "mean": float(values.mean()),
        "count": float(values.size),
    }
