"""The depth subscriptions of a pool worker's cameras (services/detector/membership.py): one for
each camera it serves that is announced with depth (``<robot>/camera/<cam>/depth``,
services/detector/depth_stage.py), dropped when the camera is lost or stops announcing depth."""

from __future__ import annotations

import threading
from functools import partial

from common.bus import Declared
from common.node import Node
from common.pool_rule import label
from services.detector.handlers import DetectorHandlers


class PoolDepth:
    """The depth subscriptions of the cameras served. ``keys`` (pool name -> depth key, of the
    cameras announced with depth) is set by the loop as the announcements change; :meth:`sync`
    and :meth:`close` are the loop's, outside any lock of the caller's. Its own lock covers its
    dicts (the loop alone writes them; the lock keeps a close from another thread safe)."""

    def __init__(self, node: Node, handlers: DetectorHandlers) -> None:
        self.node = node
        self.handlers = handlers
        self.keys: dict[str, str] = {}
        self._lock = threading.Lock()
        self._subs: dict[str, tuple[str, Declared]] = {}  # label -> (depth key, sub)

    def sync(self, serving: frozenset[str]) -> None:
        """A depth subscription for each camera of ``serving`` announced with depth, and none
        for another (a camera lost, or no longer announcing depth: its depth let go)."""
        with self._lock:
            wanted = {label(c): k for c, k in self.keys.items() if c in serving}
            gone = [
                (cam, self._subs.pop(cam)[1])
                for cam, (key, _) in list(self._subs.items())
                if wanted.get(cam) != key
            ]
            new = {cam: key for cam, key in wanted.items() if cam not in self._subs}
        depth = self.handlers.depth
        for cam, sub in gone:
            sub.undeclare()
            depth.drop_camera(cam)
        added: dict[str, tuple[str, Declared]] = {}
        for cam, key in new.items():
            depth.add_camera(cam, key)
            on_depth = partial(self.handlers.on_depth, cam)
            added[cam] = (key, self.node.subscribe_bounded(key, on_depth))
        with self._lock:
            self._subs.update(added)
        if gone or added:
            self.node.log.info(
                "depth paired on %s (stopped on %s)",
                sorted(wanted) or "no camera",
                sorted(cam for cam, _ in gone) or "none",
            )

    def close(self) -> None:
        with self._lock:
            subs = [sub for _, sub in self._subs.values()]
            self._subs.clear()
        for sub in subs:
            sub.undeclare()
