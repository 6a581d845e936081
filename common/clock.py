"""The stack's clocks: the one module that reads them (tests/unit/common/test_clock_only.py).

Stamps on two clocks: the wall clock every host shares (roughly) and this host's monotonic one.
A message carries both. A receiver on the same boot of the same host judges age on the monotonic
clock too, which no NTP step or operator's ``date`` moves; a receiver on another host can only
use the wall clock, which must then be synchronised (docs/security.md, "Clocks").

Which clock for what: :func:`wall_ns` for stamps that cross processes, :func:`mono_s` for
deadlines, periods and ages within a process, :func:`perf_s` (with :func:`ms_since`) for timing
stages, :func:`local_now` and :func:`utc_now` for dates that people read.
"""

from __future__ import annotations

import datetime
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol


def _read_boot_id() -> str:
    """This boot's id (Linux); monotonic stamps compare only within one boot of one host."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text(encoding="ascii").strip()
    except OSError:
        return ""  # not Linux: monotonic stamps are then never compared across processes


BOOT_ID = _read_boot_id()


@dataclass(frozen=True, slots=True)
class Stamp:
    """One instant on both clocks, in integer nanoseconds."""

    wall_ns: int
    mono_ns: int


def now() -> Stamp:
    return Stamp(time.time_ns(), time.monotonic_ns())


def wall_ns() -> int:
    """Wall-clock time in ns since the Unix epoch: the stamp messages carry across processes."""
    return time.time_ns()


def mono_ns() -> int:
    """This host's monotonic clock in ns; compares only within one boot (:data:`BOOT_ID`)."""
    return time.monotonic_ns()


def mono_s() -> float:
    """This host's monotonic clock in seconds: deadlines, periods and ages within a process."""
    return time.monotonic()


def mono_to_unix_s() -> float:
    """What to add to a :func:`mono_s` reading to get Unix seconds (as the wall clock is now)."""
    return time.time() - time.monotonic()


def perf_s() -> float:
    """The finest timer, in seconds, for timing a stage; only differences between readings
    mean anything."""
    return time.perf_counter()


def perf_ns() -> int:
    """:func:`perf_s` in integer ns."""
    return time.perf_counter_ns()


def cpu_s() -> float:
    """This process's CPU time in seconds (every thread's): a benchmark's measure of work
    that other processes' load does not lengthen; only differences mean anything."""
    return time.process_time()


def ms_since(start_perf_s: float) -> float:
    """Milliseconds since ``start_perf_s``, a :func:`perf_s` reading."""
    return (time.perf_counter() - start_perf_s) * 1e3


def local_now() -> datetime.datetime:
    """The local date and time (naive), for names a person reads: a recording's file name."""
    return datetime.datetime.now()


def utc_now() -> datetime.datetime:
    """The date and time in UTC (aware), for what is written down: certificates, reports."""
    return datetime.datetime.now(datetime.UTC)


class Clock(Protocol):
    """What a loop, a pool member or a window reads the time from: the system's clocks in a
    process, a :class:`FakeClock` in an in-process test."""

    def now(self) -> Stamp: ...

    def mono_s(self) -> float: ...

    def wall_ns(self) -> int: ...


class SystemClock:
    """The host's clocks (:func:`now`, :func:`mono_s`, :func:`wall_ns`)."""

    def now(self) -> Stamp:
        return now()

    def mono_s(self) -> float:
        return mono_s()

    def wall_ns(self) -> int:
        return wall_ns()


SYSTEM_CLOCK = SystemClock()


class FakeClock:
    """A clock that moves only when told (:meth:`advance`): both readings move together, so
    that a stamp's age on either is the same. Starts at a plausible wall time, and at a
    monotonic reading far from zero (so that "0" never reads as a fresh instant)."""

    def __init__(self, wall_ns: int = 1_790_000_000 * 10**9, mono_ns: int = 10_000 * 10**9):
        self._wall_ns = wall_ns
        self._mono_ns = mono_ns

    def advance(self, seconds: float) -> None:
        if seconds < 0:
            raise ValueError("a monotonic clock never goes back")
        step = round(seconds * 1e9)
        self._wall_ns += step
        self._mono_ns += step

    def now(self) -> Stamp:
        return Stamp(self._wall_ns, self._mono_ns)

    def mono_s(self) -> float:
        return self._mono_ns / 1e9

    def wall_ns(self) -> int:
        return self._wall_ns
