"""Our presence in a ROS 2 graph over rmw_zenoh: a node, its publishers and its subscribers.

I/O: this module owns the Zenoh session to the robot's router. Each publisher puts CDR with the
33-byte attachment rmw_zenoh subscribers require, and each endpoint declares the liveliness
token that ``ros2 node list`` / ``ros2 topic list`` read (rosmsg/wire.py has the format).
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections.abc import Callable
from typing import Literal, Protocol

import zenoh

from common.clock import wall_ns
from common.lifecycle import Closing
from common.zenoh_bus import RosRouter, open_ros_session
from rosmsg.convert import RosMessage, cdr_encode
from rosmsg.distro import RosDistro
from rosmsg.wire import (
    DEFAULT_QOS,
    Attachment,
    RosQoS,
    data_key,
    endpoint_token,
    gid_for,
    node_token,
)

log = logging.getLogger("ros2")


class RosNode(RosRouter, Protocol):
    """Where a node stands in a ROS 2 graph: its router (``RosRouter``), domain, distribution,
    name and namespace (the ros2 bridge's settings, services/ros2/contract.py, are one)."""

    @property
    def domain_id(self) -> int: ...

    @property
    def distro(self) -> RosDistro: ...

    @property
    def node(self) -> str: ...

    @property
    def namespace(self) -> str: ...


class RosPublisher:
    """One ROS 2 publisher: CDR payload plus attachment on the rmw_zenoh data key.

    Thread-safe: a put from a callback still running while the bridge stops cannot meet the
    undeclare (zenoh's publisher refuses concurrent use: "Already borrowed"); once closed, a
    put is dropped (the bridge is stopping, its robot already sent zero)."""

    def __init__(self, graph: RosGraph, topic: str, ros_type: str, qos: RosQoS) -> None:
        self.ros_type = ros_type
        self._distro = graph.settings.distro
        self.key = graph.key(topic, ros_type)
        token = graph.token("MP", topic, ros_type, qos)
        self._gid = gid_for(token)
        self._seq = itertools.count(1)
        self._pub = graph.session.declare_publisher(self.key)
        self._token = graph.session.liveliness().declare_token(token)
        self._lock = threading.Lock()
        self._closed = False

    def put(self, msg: RosMessage) -> None:
        self.put_cdr(cdr_encode(self._distro, self.ros_type, msg))

    def put_cdr(self, payload: bytes) -> None:
        with self._lock:
            if self._closed:
                return
            attachment = Attachment(next(self._seq), wall_ns(), self._gid)
            self._pub.put(payload, attachment=attachment.encode())

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._token.undeclare()
            self._pub.undeclare()


class RosGraph(Closing):
    """A node in the robot's ROS 2 graph (or, with ``host``, the graph's router itself)."""

    def __init__(self, settings: RosNode, *, host: bool = False) -> None:
        self.settings = settings
        self.session = open_ros_session(settings, host=host)
        self._zid = str(self.session.zid())
        self._eid = itertools.count(1)
        self._nid = 0
        self._closers: list[Callable[[], None]] = []
        token = node_token(
            settings.domain_id, self._zid, self._nid, settings.namespace, settings.node
        )
        node = self.session.liveliness().declare_token(token)
        self._closers.append(node.undeclare)

    def key(self, topic: str, ros_type: str) -> str:
        s = self.settings
        return data_key(s.domain_id, topic, ros_type, s.distro, s.namespace)

    def token(self, kind: Literal["MP", "MS"], topic: str, ros_type: str, qos: RosQoS) -> str:
        s = self.settings
        return endpoint_token(
            kind, domain_id=s.domain_id, zid=self._zid, nid=self._nid, eid=next(self._eid),
            namespace=s.namespace, node=s.node, topic=topic, ros_type=ros_type,
            distro=s.distro, qos=qos,
        )  # fmt: skip

    def publisher(self, topic: str, ros_type: str, qos: RosQoS = DEFAULT_QOS) -> RosPublisher:
        pub = RosPublisher(self, topic, ros_type, qos)
        self._closers.append(pub.close)
        return pub

    def subscribe(
        self,
        topic: str,
        ros_type: str,
        on_payload: Callable[[str, memoryview], None],
        qos: RosQoS = DEFAULT_QOS,
    ) -> str:
        """Call ``on_payload(key, cdr)`` for each sample on ``topic``; returns the data key.

        The attachment is not required here: only rmw_zenoh's own subscribers insist on it.
        """
        key = self.key(topic, ros_type)

        def on_sample(sample: zenoh.Sample) -> None:
            on_payload(key, memoryview(sample.payload.to_bytes()))

        sub = self.session.declare_subscriber(key, on_sample)
        token = self.session.liveliness().declare_token(self.token("MS", topic, ros_type, qos))
        self._closers += [sub.undeclare, token.undeclare]
        return key

    def on_close(self, close: Callable[[], None]) -> None:
        """Call ``close`` when the graph closes (before its session does)."""
        self._closers.append(close)

    def close(self) -> None:
        """Undeclare everything, then close the session: always, whatever an undeclare
        raises (a session left open keeps the process from exiting, and its callbacks
        running against a closed stack)."""
        try:
            for close in reversed(self._closers):
                try:
                    close()
                except Exception:  # logged; the others and the session still close
                    log.exception("closing the ROS 2 graph: an undeclare failed")
        finally:
            self.session.close()
