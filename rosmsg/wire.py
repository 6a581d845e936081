"""The rmw_zenoh wire format: data keys, the per-sample attachment and the liveliness tokens.

Everything here is read from rmw_zenoh's released sources (Humble 0.1.9, Jazzy 0.2.10, Kilted
0.6.7, Rolling 0.12.0: ``liveliness_utils.cpp``, ``attachment_helpers.cpp``); docs/ros2.md
states the format. The
distributions differ only in the type hash: ``TypeHashNotSupported`` on Humble, REP-2016's
``RIHS01_<sha256>`` from Jazzy on. No zenoh here: these are the strings and bytes a session puts.
"""

from __future__ import annotations

import functools
import re
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

import xxhash

from common.errors import DecodeError
from rosmsg.distro import RosDistro
from rosmsg.typestore import typestore_for

HUMBLE_TYPE_HASH = "TypeHashNotSupported"
ADMIN_SPACE = "@ros2_lv"
GID_SIZE = 16

# int64 LE sequence number, int64 LE source timestamp (ns), then the GID as zenoh's serializer
# writes a std::array<uint8_t, 16>: its length as one LEB128 byte (0x10) and the 16 bytes.
_ATTACHMENT = struct.Struct(f"<qqB{GID_SIZE}s")
ATTACHMENT_SIZE = _ATTACHMENT.size  # 33
_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1

_ROS_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(msg|srv|action)/([A-Za-z][A-Za-z0-9_]*)$")


def dds_type(ros_type: str) -> str:
    """The type name rmw_zenoh puts in keys: ``pkg/msg/Type`` -> ``pkg::msg::dds_::Type_``."""
    match = _ROS_TYPE.match(ros_type)
    if match is None:
        raise ValueError(f"not a ROS 2 type name (pkg/msg/Type): {ros_type!r}")
    package, kind, name = match.groups()
    return f"{package}::{kind}::dds_::{name}_"


@functools.cache
def type_hash(distro: RosDistro, ros_type: str) -> str:
    """The type hash segment of keys and tokens: RIHS01 from Jazzy on, a literal on Humble."""
    dds_type(ros_type)  # refuse a malformed name on every distribution
    if RosDistro(distro) is RosDistro.HUMBLE:
        return HUMBLE_TYPE_HASH
    store = typestore_for(RosDistro(distro))
    if ros_type not in store.types:
        raise ValueError(f"{ros_type} is not a known {distro} type")
    return store.hash_rihs01(ros_type)


def fully_qualified(topic: str, namespace: str = "/") -> str:
    """``topic`` as ROS names it: absolute, no trailing or doubled '/'; relative ones joined to
    ``namespace``. Refuses names a zenoh key cannot hold."""
    name = topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"
    name = name.rstrip("/")
    if not name or "//" in name or any(c in name for c in "*$?#% \t\n"):
        raise ValueError(f"not a valid ROS topic name: {topic!r} in namespace {namespace!r}")
    return name


def data_key(
    domain_id: int, topic: str, ros_type: str, distro: RosDistro, namespace: str = "/"
) -> str:
    """The key samples travel on: ``<domain>/<topic>/<pkg>::msg::dds_::<Type>_/<hash>``, the
    topic fully qualified without its leading '/' (``0/cmd_vel/geometry_msgs::msg::...``)."""
    if domain_id < 0:
        raise ValueError(f"ROS domain id must be >= 0, got {domain_id}")
    name = fully_qualified(topic, namespace).strip("/")
    return f"{domain_id}/{name}/{dds_type(ros_type)}/{type_hash(distro, ros_type)}"


def gid_for(token: str) -> bytes:
    """The 16-byte GID rmw_zenoh gives the entity whose liveliness token is ``token``.

    rmw_zenoh_cpp (``liveliness_utils.cpp``, ``Entity``'s constructor) hashes the whole
    liveliness key expression with XXH3-128 (seed 0, default secret: its
    ``simplified_xxhash3.cpp`` is the portable reference code) and copies ``low64`` then
    ``high64``, each in the host's little-endian order. So a ROS 2 graph that derives the
    bridge's GID from its token finds the same GID in the bridge's samples.
    """
    digest = xxhash.xxh3_128_intdigest(token.encode("utf-8"))
    return digest.to_bytes(GID_SIZE, "little")  # low64 LE, then high64 LE


@dataclass(frozen=True, slots=True)
class Attachment:
    """What rmw_zenoh requires beside every sample; subscribers drop a sample without one.

    ``sequence_number`` counts a publisher's samples from 1; ``source_timestamp_ns`` is the
    publisher's system clock when it published, in ns since the epoch.
    """

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def __post_init__(self) -> None:
        if len(self.gid) != GID_SIZE:
            raise ValueError(f"a GID is {GID_SIZE} bytes, got {len(self.gid)}")
        for value in (self.sequence_number, self.source_timestamp_ns):
            if not _INT64_MIN <= value <= _INT64_MAX:
                raise ValueError(f"{value} does not fit an int64")

    def encode(self) -> bytes:
        return _ATTACHMENT.pack(
            self.sequence_number, self.source_timestamp_ns, GID_SIZE, bytes(self.gid)
        )

    @classmethod
    def decode(cls, data: bytes | bytearray | memoryview) -> Attachment:
        """Parse an attachment; anything but the 33-byte layout raises DecodeError."""
        if len(data) != ATTACHMENT_SIZE:
            raise DecodeError(
                f"rmw_zenoh attachment must be {ATTACHMENT_SIZE} bytes, got {len(data)}"
            )
        sequence_number, stamp_ns, gid_len, gid = _ATTACHMENT.unpack(data)
        if gid_len != GID_SIZE:
            raise DecodeError(f"rmw_zenoh attachment GID length byte is {gid_len}, not {GID_SIZE}")
        return cls(sequence_number, stamp_ns, gid)


class Reliability(IntEnum):
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(IntEnum):
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(IntEnum):
    KEEP_LAST = 1
    KEEP_ALL = 2


class Liveliness(IntEnum):
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3


# rmw's RMW_DURATION_INFINITE as (sec, nsec): the default of every duration in the QoS string.
_INFINITE = (9223372036, 854775807)
# rmw_zenoh's own defaults (qos.cpp); a field equal to its default is written empty.
_ZENOH_DEFAULT_DEPTH = 42


@dataclass(frozen=True, slots=True, kw_only=True)
class RosQoS:
    """A ROS 2 QoS profile as a liveliness token carries it (not common.zenoh_bus.QoS, our roles).
    Durations in ns; None is infinite.

    The defaults are ROS's default profile (reliable, volatile, keep last 10).
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10
    deadline_ns: int | None = None
    lifespan_ns: int | None = None
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease_ns: int | None = None

    def __post_init__(self) -> None:
        if self.depth < 0:
            raise ValueError(f"QoS depth must be >= 0, got {self.depth}")
        for ns in (self.deadline_ns, self.lifespan_ns, self.liveliness_lease_ns):
            if ns is not None and ns < 0:
                raise ValueError(f"QoS durations must be >= 0 ns, got {ns}")


DEFAULT_QOS = RosQoS()
# rmw_qos_profile_sensor_data: what camera and lidar drivers publish with.
SENSOR_DATA_QOS = RosQoS(reliability=Reliability.BEST_EFFORT, depth=5)


def _field(value: int, default: int) -> str:
    return "" if value == default else str(int(value))


def _duration(ns: int | None) -> str:
    sec, nsec = _INFINITE if ns is None else divmod(ns, 1_000_000_000)
    return f"{_field(sec, _INFINITE[0])},{_field(nsec, _INFINITE[1])}"


def qos_string(qos: RosQoS = DEFAULT_QOS) -> str:
    """The token's QoS chunk, ``R:D:H,depth:dl_s,dl_ns:ls_s,ls_ns:lv,lv_s,lv_ns``, with each
    field equal to rmw_zenoh's default left empty (so ROS's default profile is ``::,10:,:,:,,``).
    """
    return ":".join(
        (
            _field(qos.reliability, Reliability.RELIABLE),
            _field(qos.durability, Durability.VOLATILE),
            f"{_field(qos.history, History.KEEP_LAST)},{_field(qos.depth, _ZENOH_DEFAULT_DEPTH)}",
            _duration(qos.deadline_ns),
            _duration(qos.lifespan_ns),
            f"{_field(qos.liveliness, Liveliness.AUTOMATIC)},{_duration(qos.liveliness_lease_ns)}",
        )
    )


def mangle(name: str) -> str:
    """A ROS name as one key chunk: every '/' becomes '%' (the root namespace is ``%``)."""
    return name.replace("/", "%")


def _token(chunks: list[str]) -> str:
    for chunk in chunks:
        # rmw_zenoh's parser drops a token with an empty chunk; zenoh refuses wildcards.
        if not chunk or any(c in chunk for c in "/*$?#"):
            raise ValueError(f"invalid liveliness token chunk {chunk!r} in {chunks}")
    return "/".join(chunks)


def node_token(
    domain_id: int, zid: str, nid: int, namespace: str, node: str, enclave: str = "/"
) -> str:
    """A node's liveliness key: ``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<ns>/<node>``.

    ``zid`` is the session id in hex (``str(session.zid())``); ``nid`` unique in the session.
    """
    return _token(
        [
            ADMIN_SPACE,
            str(domain_id),
            zid,
            str(nid),
            str(nid),
            "NN",
            mangle(enclave),
            mangle(namespace),
            mangle(node),
        ]
    )


def endpoint_token(
    kind: Literal["MP", "MS"],
    *,
    domain_id: int,
    zid: str,
    nid: int,
    eid: int,
    namespace: str,
    node: str,
    topic: str,
    ros_type: str,
    distro: RosDistro,
    qos: RosQoS = DEFAULT_QOS,
    enclave: str = "/",
) -> str:
    """A publisher's (MP) or subscriber's (MS) liveliness key, 13 chunks: the node's, then
    the mangled topic, the DDS type name, the type hash and the QoS string."""
    if kind not in ("MP", "MS"):
        raise ValueError(f"endpoint kind must be MP or MS, got {kind!r}")
    return _token(
        [
            ADMIN_SPACE,
            str(domain_id),
            zid,
            str(nid),
            str(eid),
            kind,
            mangle(enclave),
            mangle(namespace),
            mangle(node),
            mangle(fully_qualified(topic, namespace)),
            dds_type(ros_type),
            type_hash(distro, ros_type),
            qos_string(qos),
        ]
    )
