"""How the in-memory bus (common/memory_bus.py) hands a sample or a token's event to its
receiver: in the putting thread (:class:`Inline`, the default: deterministic, a test reads the
result on the next line), or on threads of its own (:class:`Threaded`), as Zenoh does.

Zenoh calls each subscription's (and each liveliness watch's) callback on threads of its
own, one sample after the other in the order they came, while other subscriptions' callbacks
run at the same time. A test on the inline bus cannot see what that allows: a token's event
handled while the loop is between two reads of the state it changes, two handlers of one
participant at once, a sample heard before the announcement that explains it. ``Threaded``
gives every declaration a lane: a lane's calls run one at a time, in the order they were
submitted; which waiting lane a free thread takes next is drawn from a ``random.Random(seed)``,
so lanes interleave in a shuffled order, and with several threads at once. A test then waits
for what it put to be handled with :meth:`Threaded.drain`, never a sleep.
"""

from __future__ import annotations

import random
import threading
from collections import deque
from collections.abc import Callable
from typing import Protocol

from common.clock import mono_s

#: The longest :meth:`Delivery.drain` waits for the deliveries under way to end.
DRAIN_TIMEOUT_S = 10.0

Call = Callable[[], object]


class Delivery(Protocol):
    """Runs a receiver's call (``lane``: the declaration whose call it is)."""

    def submit(self, lane: object, call: Call) -> None: ...

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> None: ...

    def close(self) -> None: ...


class Inline:
    """Each call at once, in the submitting thread; an exception reaches the submitter."""

    def submit(self, lane: object, call: Call) -> None:
        call()

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> None:
        return None  # nothing is ever under way

    def close(self) -> None:
        return None


class Threaded:
    """Calls run on ``threads`` threads of their own: one at a time per lane, in order; the
    next lane drawn by a ``random.Random(seed)`` among those waiting.

    A receiver's exception does not end its thread (Zenoh logs it and goes on); the next
    :meth:`drain` raises it, so that it still reaches the test.
    """

    def __init__(self, threads: int = 2, seed: int | None = None) -> None:
        if threads < 1:
            raise ValueError(f"a threaded delivery needs at least one thread, got {threads}")
        self._cond = threading.Condition()
        self._lanes: dict[object, deque[Call]] = {}
        self._busy: set[object] = set()
        self._pending = 0  # submitted and not yet returned
        self._errors: list[Exception] = []
        self._rng = random.Random(seed)
        self._closed = False
        self._threads = [
            threading.Thread(target=self._run, name=f"memory-bus-{n}", daemon=True)
            for n in range(threads)
        ]
        for thread in self._threads:
            thread.start()

    def submit(self, lane: object, call: Call) -> None:
        with self._cond:
            if self._closed:
                return  # the hub is gone: nobody hears anything more
            self._lanes.setdefault(lane, deque()).append(call)
            self._pending += 1
            self._cond.notify()

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> None:
        """Wait until every call submitted (those the calls submit too) has returned; raise
        the first exception a receiver raised since the last drain."""
        if threading.current_thread() in self._threads:
            raise RuntimeError("drain() on a delivery thread would wait for itself")
        deadline = mono_s() + timeout_s
        with self._cond:
            while self._pending:
                left = deadline - mono_s()
                if left <= 0:
                    raise TimeoutError(
                        f"{self._pending} deliveries still under way after {timeout_s:g} s"
                    )
                self._cond.wait(left)
            errors, self._errors = self._errors, []
        if errors:
            raise errors[0]

    def close(self) -> None:
        """End the threads once the calls under way return; what waits is dropped."""
        with self._cond:
            self._closed = True
            self._pending -= sum(len(q) for q in self._lanes.values())
            self._lanes.clear()
            self._cond.notify_all()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(DRAIN_TIMEOUT_S)

    def _take(self) -> tuple[object, Call] | None:
        """A waiting lane's next call (the lane drawn at random), or None; under the lock."""
        ready = [lane for lane, calls in self._lanes.items() if lane not in self._busy]
        if not ready:
            return None
        lane = ready[self._rng.randrange(len(ready))]
        calls = self._lanes[lane]
        call = calls.popleft()
        if not calls:
            del self._lanes[lane]
        self._busy.add(lane)
        return lane, call

    def _run(self) -> None:
        while True:
            with self._cond:
                while (taken := self._take()) is None:
                    if self._closed:
                        return
                    self._cond.wait()
            lane, call = taken
            try:
                call()
            except Exception as exc:  # kept for drain(): the test hears of it there
                with self._cond:
                    self._errors.append(exc)
            finally:
                with self._cond:
                    self._busy.discard(lane)
                    self._pending -= 1
                    self._cond.notify_all()
