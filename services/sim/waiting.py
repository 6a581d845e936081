"""What the simulator's scenario clock waits for (``sim.wait_for``) before the world moves.

A service named there is waited for by what will really come of it, not by where it would run:
``detector`` is the detections of every camera the simulator renders, from whichever worker
serves them (this host's, or a pool's on a GPU box, whose health token lives under another
prefix); any other service by its health token under the stack's prefix. While it waits, the
world stands still and a WARNING line says every :data:`WARN_PERIOD_S` what it still waits
for, so that a robot standing still says why.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable

from common.bus import Bus, Declared
from common.keys import Keys

#: How often a simulator still waiting says what for (seconds).
WARN_PERIOD_S = 5.0
DETECTOR = "detector"


class Waiting:
    """The scenario clock's conditions: :meth:`missing` names those not met yet (empty: the
    clock may start). ``live(key)`` says whether a health token is live on ``key``."""

    def __init__(
        self,
        bus: Bus,
        keys: Keys,
        services: Iterable[str],
        cameras: Iterable[str],
        live: Callable[[str], bool],
    ) -> None:
        self._keys = keys
        self._live = live
        wanted = list(services)
        self._services = [s for s in wanted if s != DETECTOR]
        self._cameras = list(cameras) if DETECTOR in wanted else []
        self._heard: set[str] = set()
        self._lock = threading.Lock()
        self._subs: list[Declared] = [
            bus.subscribe(keys.detections(c), self._on_detections(c)) for c in self._cameras
        ]

    def _on_detections(self, camera: str) -> Callable[[object], None]:
        def heard(_sample: object) -> None:
            with self._lock:
                self._heard.add(camera)

        return heard

    def missing(self) -> list[str]:
        """What the clock still waits for, one phrase each, in the order configured."""
        with self._lock:
            unheard = [c for c in self._cameras if c not in self._heard]
        out = []
        if unheard:
            out.append(
                f"detections of camera(s) {', '.join(unheard)} (a detector worker serving "
                "them: this stack's, or a pool's)"
            )
        out += [
            f"{s} ready (its health token {self._keys.health(s)})"
            for s in self._services
            if not self._live(self._keys.health(s))
        ]
        return out

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def waiting_line(missing: list[str], waited_s: float) -> str:
    """The WARNING line of a simulator still waiting: what for, and since when."""
    return (
        f"the scenario clock has waited {waited_s:.0f} s (sim.wait_for); the world stands "
        f"still until: {'; '.join(missing)}"
    )
