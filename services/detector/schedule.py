"""Which frames the detector runs next: one latest-only slot per camera, taken in fair rounds.

Each camera has one slot. A frame replaces the one waiting there (that one is dropped and
counted by the caller): queueing would make every detection later than the last, and the
newest frame is the one worth detecting on.

A *round* takes the waiting frame of up to ``max_batch`` cameras, those that have waited
longest first. A camera's wait starts when its slot fills after being emptied, and a newer
frame replacing the waiting one does not restart it; so a camera sending 100 frames a second
stays in its place in the queue like one sending 5, and a camera that was just served goes
to the back. Hence the bound the unit tests prove: with ``n`` cameras, a camera with a frame
waiting is served within ``ceil(n / max_batch)`` rounds, whatever the others' rates, since
at most ``n - 1`` cameras can be ahead of it and every round serves the ``max_batch`` oldest.

A round may be taken in another :class:`Order` (services/detector/attention.py: the target's
cameras first, every other camera at a floor rate). The order is handed the waiting cameras
longest-waiting first and may only rearrange them; without one, or when it leaves them as
they are, the rounds are the fair ones above.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from common.clock import SYSTEM_CLOCK, Clock

_T = TypeVar("_T")


@dataclass(frozen=True, slots=True)
class Waiting(Generic[_T]):
    """A camera's newest frame as a round takes it: ``received_ns`` is when that frame
    arrived (the slots' clock's ``wall_ns()``)."""

    camera: str
    item: _T
    received_ns: int
    reason: str = ""  # why the round took it, as the Order said ("" without one)


class Order(Protocol):
    """The order in which a round takes the waiting cameras."""

    def arrange(self, cameras: Sequence[str]) -> list[tuple[str, str]]:
        """``cameras`` (those with a frame waiting, longest-waiting first) in the order to
        take them, each with the reason it is where it is; the same cameras, each once."""
        ...

    def taken(self, cameras: Sequence[str]) -> None:
        """``cameras`` were taken in a round, now."""
        ...


@dataclass(slots=True)
class _Slot(Generic[_T]):
    item: _T
    received_ns: int
    since: int  # the arrival ticket of the frame that started this wait (smaller = older)


class CameraSlots(Generic[_T]):
    """One latest-only slot per camera (thread-safe: Zenoh's threads put, the loop takes); a
    frame's arrival is stamped on ``clock``. Cameras may be added later (:meth:`add`: a
    camera announced at run time)."""

    def __init__(self, cameras: Iterable[str] = (), clock: Clock = SYSTEM_CLOCK) -> None:
        self.cameras: tuple[str, ...] = tuple(cameras)
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"cameras must be distinct, got {self.cameras}")
        self._cond = threading.Condition()
        self._slots: dict[str, _Slot[_T]] = {}
        self._tickets = itertools.count()
        self._clock = clock

    def put(self, camera: str, item: _T) -> bool:
        """Leave ``item`` in ``camera``'s slot; True when it replaced one nobody took (a drop).

        KeyError for a camera not given at construction.
        """
        if camera not in self.cameras:
            raise KeyError(camera)
        received = self._clock.wall_ns()
        with self._cond:
            ticket = next(self._tickets)
            slot = self._slots.get(camera)
            if slot is not None:
                slot.item, slot.received_ns = item, received  # keeps its place: slot.since
                return True
            self._slots[camera] = _Slot(item, received, ticket)
            self._cond.notify()
        return False

    def add(self, camera: str) -> None:
        """A slot for ``camera`` too (nothing when it has one)."""
        with self._cond:
            if camera not in self.cameras:
                self.cameras = (*self.cameras, camera)

    def take(self, max_batch: int, timeout: float, order: Order | None = None) -> list[Waiting[_T]]:
        """The next round: the waiting frames of at most ``max_batch`` cameras, those waiting
        longest first, or first in ``order``; empty after ``timeout`` seconds with nothing
        waiting."""
        if max_batch < 1:
            raise ValueError(f"max_batch must be at least 1, got {max_batch}")
        with self._cond:
            if not self._slots and not self._cond.wait_for(lambda: bool(self._slots), timeout):
                return []
            oldest = sorted(self._slots, key=lambda cam: self._slots[cam].since)
            arranged = [(cam, "") for cam in oldest] if order is None else order.arrange(oldest)
            if sorted(cam for cam, _ in arranged) != sorted(oldest):
                raise ValueError(f"the order {arranged} is not a rearrangement of {oldest}")
            chosen = arranged[:max_batch]
            taken = [(cam, why, self._slots.pop(cam)) for cam, why in chosen]
            if order is not None:
                order.taken([cam for cam, _ in chosen])
        return [Waiting(cam, slot.item, slot.received_ns, why) for cam, why, slot in taken]

    def clear(self, camera: str) -> bool:
        """Drop ``camera``'s waiting frame, if any (its camera went to another worker); True
        when there was one."""
        with self._cond:
            return self._slots.pop(camera, None) is not None

    def waiting(self) -> int:
        """How many cameras have a frame waiting."""
        with self._cond:
            return len(self._slots)
