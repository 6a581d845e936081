"""What a pool worker hears of the pool's announcements (services/detector/membership.py): every
worker's (a WorkerAnnouncement under the pool's prefix) and every camera announced under each
robot prefix it serves, each through common/announce.py's :class:`Announced` (the newest of a
name, garbage reported to ``on_bad`` and ignored). The bus's threads call ``on_change``; the
detection loop reads what is heard (:meth:`PoolHearing.workers`, :meth:`PoolHearing.cameras`)
when it settles. Each listener takes only its own lock."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from common.announce import (
    Announced,
    announced_cameras,
    announced_workers,
    cameras_now,
    workers_now,
)
from common.bus import Bus
from common.keys import Keys
from common.messages import CameraAnnouncement
from common.pool_rule import pool_name
from services.detector.pool import PoolCamera, PoolWorker

#: How long a joining worker asks who is already in the pool before it takes its cameras: the
#: query ends as soon as every peer answered; this bounds it on a slow link.
POOL_ASK_TIMEOUT_S = 1.0
CATCH_UP_CHECKS = 20  # how often a joining worker looks whether it heard every announcement


class PoolHearing:
    """The pool's announcements as a worker hears them: the workers' under ``pool_keys``, the
    cameras' under each of ``prefixes``. ``on_change()`` whenever either changed (on the bus's
    thread, no lock held); ``on_bad(key, error)`` for an announcement that does not decode."""

    def __init__(
        self,
        bus: Bus,
        pool_keys: Keys,
        prefixes: tuple[str, ...] | list[str],
        on_change: Callable[[], None],
        on_bad: Callable[[str, Exception], None],
    ) -> None:
        self._bus = bus
        self._pool_keys = pool_keys
        self._on_change = on_change
        self._heard = threading.Event()  # an announcement came or went
        self._workers = announced_workers(bus, pool_keys, self._changed, on_bad)
        self._cameras: dict[str, Announced[CameraAnnouncement]] = {
            prefix: announced_cameras(bus, Keys(prefix), self._changed, on_bad)
            for prefix in prefixes
        }

    def _changed(self) -> None:
        self._heard.set()
        self._on_change()

    def catch_up(self) -> None:
        """Wait (at most :data:`POOL_ASK_TIMEOUT_S`) until the listeners hold every
        announcement alive on the bus now, so that the first assignment is the pool's, not
        that of a worker that believes itself alone (which would serve every camera for a
        moment). On an in-process bus they are there at once. The names to wait for are those
        of the announcements a look at the bus reads (common/announce.py's one-shot form):
        garbage is no name to wait for, and the listeners report it (once)."""
        bus, timeout_s = self._bus, POOL_ASK_TIMEOUT_S
        expected: list[tuple[Announced[Any], set[str]]] = [
            (self._workers, set(workers_now(bus, self._pool_keys, timeout_s)))
        ]
        for prefix, heard in self._cameras.items():
            expected.append((heard, set(cameras_now(bus, Keys(prefix), timeout_s))))
        for _ in range(CATCH_UP_CHECKS):
            if all(names <= heard.current().keys() for heard, names in expected):
                return
            self._heard.wait(POOL_ASK_TIMEOUT_S / CATCH_UP_CHECKS)
            self._heard.clear()

    def workers(self) -> dict[str, list[PoolWorker]]:
        """Every live announcement of each worker (more than one while two sessions announce
        a name), as the pool counts it: its capacity and the robots it serves (none named:
        the pool's own prefix)."""
        pool = self._pool_keys.prefix
        return {
            w: [PoolWorker(a.capacity_hz, frozenset(a.prefixes or (pool,))) for a in heard]
            for w, heard in self._workers.every().items()
        }

    def cameras(self) -> tuple[dict[str, PoolCamera], dict[str, str]]:
        """Every camera heard, by the name the pool gives it (common/pool_rule.py), and the
        depth key (``<robot>/camera/<cam>/depth``) of each announced with depth."""
        pool = self._pool_keys.prefix
        heard = [
            (prefix, cam, a)
            for prefix, announced in self._cameras.items()
            for cam, a in announced.current().items()
        ]
        announced = {
            pool_name(prefix, cam, pool): PoolCamera(prefix, cam, a.rate_hz, a.hfov_deg)
            for prefix, cam, a in heard
        }
        depth = {
            pool_name(prefix, cam, pool): Keys(prefix).depth(cam)
            for prefix, cam, a in heard
            if a.depth
        }
        return announced, depth

    def close(self) -> None:
        for heard in self._cameras.values():
            heard.close()
        self._workers.close()
