"""The words a service's contract (``services/<name>/contract.py``) declares its bus use in.

Pure: no bus, no Zenoh. ``Access`` is what one principal may do on the bus: the keys it puts
on, the liveliness tokens it announces, the queryables it serves and the key expressions it
subscribes to. ``Shape`` is what those depend on: the stack's keys, its cameras and their
services, its detector workers, and whether it runs a live sensor. stack/access.py builds the
router's access-control rules from every contract's declarations (docs/security.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from common.keys import Keys


@dataclass(frozen=True, slots=True)
class Access:
    """What one principal may do: put on ``put``, announce ``token``, serve ``serve``,
    subscribe within ``read`` (a subscription must lie within one of them), watch the
    liveliness tokens within ``watch`` (announcements, the pool's tokens). Anything else is
    denied."""

    put: tuple[str, ...] = ()
    token: tuple[str, ...] = ()
    serve: tuple[str, ...] = ()
    read: tuple[str, ...] = ()
    watch: tuple[str, ...] = ()

    def kinds(self) -> dict[str, tuple[str, ...]]:
        """``{kind: key expressions}`` for each kind it has any of, in the order put, token,
        read, serve, watch."""
        kinds = {
            "put": self.put,
            "token": self.token,
            "read": self.read,
            "serve": self.serve,
            "watch": self.watch,
        }
        return {kind: exprs for kind, exprs in kinds.items() if exprs}


def service_access(
    keys: Keys,
    name: str,
    *puts: str,
    read: tuple[str, ...] = (),
    token: tuple[str, ...] = (),
    serve: tuple[str, ...] = (),
    watch: tuple[str, ...] = (),
) -> Access:
    """A stack service's access: its own ``puts`` and its counters; its health token (or
    ``token`` when given: its health must be among them); what it serves, reads and
    watches."""
    return Access(
        put=(*puts, keys.counters(name)),
        token=token or (keys.health(name),),
        serve=serve,
        read=read,
        watch=watch,
    )


@dataclass(frozen=True, slots=True)
class Shape:
    """What a contract's access depends on. ``cameras``: each camera's service (and
    principal) by camera name, the first camera first; ``workers``: the detector workers'
    names, each a principal; ``live_sensors``: the stack runs a camera, the simulator or the
    ROS 2 bridge (so nothing may be played back onto their keys); ``prefixes``: the robot
    prefixes the workers serve (``detector.prefixes``; empty: the stack's own only);
    ``pool_prefix``: where their pool lives (``detector.pool_prefix``)."""

    keys: Keys
    cameras: Mapping[str, str]
    workers: tuple[str, ...]
    live_sensors: bool = True
    prefixes: tuple[str, ...] = ()
    pool_prefix: str = ""

    def pool_keys(self) -> Keys:
        """Where the workers' pool tokens and announcements live (``detector.pool_prefix``;
        empty: the stack's prefix)."""
        return Keys(self.pool_prefix) if self.pool_prefix else self.keys

    def other_robots(self) -> tuple[Keys, ...]:
        """The keys of each robot the workers serve besides the stack's own."""
        return tuple(Keys(p) for p in dict.fromkeys(self.prefixes) if p != self.keys.prefix)

    def frames(self) -> tuple[str, ...]:
        """Each configured camera's frame key: nobody may put on a camera the stack lacks."""
        return tuple(self.keys.frame(c) for c in self.cameras)
