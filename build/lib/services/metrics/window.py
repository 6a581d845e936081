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


class Timeline:
    """Per-period totals of named quantities (frames, drops ...) for the last ``span_s`` seconds.

    The live window answers "how is it now"; the timeline answers "how did it go": FPS over
    time for the query and the report's plot. Periods with nothing in them count as zeros, so a
    stalled detector shows as a dip to 0 rather than as a gap.
    """

    def __init__(self, span_s: float, period_s: float = 1.0) -> None:
        self.span_s = span_s
        self.period_s = period_s
        self._buckets: dict[int, dict[str, float]] = {}  # period index -> totals

    def _index(self, t: float) -> int:
        return int(t // self.period_s)

    def _bucket(self, index: int) -> dict[str, float]:
        return self._buckets.setdefault(index, {})

    def add(self, t: float, **amounts: float) -> None:
        """Count ``amounts`` at time ``t``."""
        bucket = self._bucket(self._index(t))
        for name, amount in amounts.items():
            bucket[name] = bucket.get(name, 0.0) + amount
        self._prune(t)

    def spread(self, start: float, end: float, **amounts: float) -> None:
        """Count ``amounts`` that accrued evenly between ``start`` and ``end``.

        For totals reported now and then (a service's counters, about once a second): putting
        each delta in the period it arrived in would alias into 0, 2, 0, 2 ...; spreading it
        over the interval it covers gives the rate that really happened.
        """
        if end <= start:
            self.add(end, **amounts)
            return
        for index in range(self._index(start), self._index(end) + 1):
            lo = max(start, index * self.period_s)
            hi = min(end, (index + 1) * self.period_s)
            share = (hi - lo) / (end - start)
            if share <= 0:
                continue
            bucket = self._bucket(index)
            for name, amount in amounts.items():
                bucket[name] = bucket.get(name, 0.0) + amount * share
        self._prune(end)

    def _prune(self, now: float) -> None:
        oldest = self._index(now - self.span_s)
        for index in [i for i in self._buckets if i < oldest]:
            del self._buckets[index]

    def series(
        self, now: float, names: tuple[str, ...], since: float | None = None
    ) -> dict[str, list[float]]:
        """Complete periods only (the current one is still filling), oldest first, gaps as 0.

        ``since`` drops the periods that begin before it (e.g. before a counter's first
        report, whose share of them is unknown). Returns ``{"t": [period start, ...],
        name: [total in that period, ...], ...}`` with times on the caller's clock.
        """
        self._prune(now)
        current = self._index(now)
        out: dict[str, list[float]] = {"t": [], **{name: [] for name in names}}
        past = [i for i in self._buckets if i < current]
        if not past:
            return out
        first = min(past) if since is None else max(min(past), -int(-since // self.period_s))
        for index in range(first, current):
            bucket = self._buckets.get(index, {})
            out["t"].append(index * self.period_s)
            for name in names:
                out[name].append(bucket.get(name, 0.0))
        return out

    def totals(self, now: float, span_s: float) -> dict[str, float]:
        """Sums over the periods that overlap the last ``span_s`` seconds, the current included."""
        self._prune(now)
        oldest = self._index(now - span_s)
        out: dict[str, float] = {}
        for index, bucket in self._buckets.items():
            if index >= oldest:
                for name, amount in bucket.items():
                    out[name] = out.get(name, 0.0) + amount
        return out
