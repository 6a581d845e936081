"""rmw_zenoh's wire format as docs/ros2.md gives it, on Humble and on Jazzy."""

from __future__ import annotations

import os
from typing import Any, Literal

import pytest
import xxhash

from common.errors import DecodeError
from rosmsg.distro import RosDistro
from rosmsg.wire import (
    ATTACHMENT_SIZE,
    DEFAULT_QOS,
    SENSOR_DATA_QOS,
    Attachment,
    Durability,
    History,
    Liveliness,
    Reliability,
    RosQoS,
    data_key,
    dds_type,
    endpoint_token,
    fully_qualified,
    gid_for,
    mangle,
    node_token,
    qos_string,
    type_hash,
)

TWIST = "geometry_msgs/msg/Twist"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
DETS_HASH = "RIHS01_214274120007f4a683866481336b70310268cfa107aebe9d594a6acf75bda968"
ZID = "a1b2c3d4e5f60718293a4b5c6d7e8f90"
#: A plain node's fields, as node_token and endpoint_token take them: tests change a few.
NODE: dict[str, Any] = {"domain_id": 0, "zid": ZID, "nid": 0, "namespace": "/", "node": "n"}


def _endpoint(kind: Literal["MP", "MS"], **fields: Any) -> str:
    """endpoint_token of a plain node's Twist endpoint on Jazzy, with ``fields`` changed."""
    twist = {"eid": 1, "topic": "/t", "ros_type": TWIST, "distro": RosDistro.JAZZY}
    return endpoint_token(kind, **(NODE | twist | fields))


def test_dds_type_names() -> None:
    assert dds_type(TWIST) == "geometry_msgs::msg::dds_::Twist_"
    assert (
        dds_type("vision_msgs/msg/Detection2DArray") == "vision_msgs::msg::dds_::Detection2DArray_"
    )
    for bad in ("Twist", "geometry_msgs/Twist", "geometry_msgs/msg/", "a/msg/B/C", ""):
        with pytest.raises(ValueError):
            dds_type(bad)


def test_type_hash_per_distro() -> None:
    assert type_hash(RosDistro.HUMBLE, TWIST) == "TypeHashNotSupported"
    for distro in (RosDistro.JAZZY, RosDistro.KILTED, RosDistro.ROLLING):
        assert type_hash(distro, TWIST) == TWIST_HASH
        assert type_hash(distro, "vision_msgs/msg/Detection2DArray") == DETS_HASH
    with pytest.raises(ValueError):
        type_hash(RosDistro.JAZZY, "nosuch_msgs/msg/Thing")


def test_data_key_the_documented_twist_example() -> None:
    expected = f"0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}"
    assert data_key(0, "/cmd_vel", TWIST, RosDistro.JAZZY) == expected
    assert data_key(0, "/cmd_vel", TWIST, RosDistro.KILTED) == expected
    assert data_key(0, "cmd_vel", TWIST, RosDistro.JAZZY) == expected  # relative, root namespace
    assert data_key(0, "/cmd_vel/", TWIST, RosDistro.JAZZY) == expected


def test_data_key_on_humble_and_other_domains_and_namespaces() -> None:
    assert (
        data_key(0, "/cmd_vel", TWIST, RosDistro.HUMBLE)
        == "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported"
    )
    assert data_key(7, "/robot1/scan", "sensor_msgs/msg/LaserScan", RosDistro.HUMBLE) == (
        "7/robot1/scan/sensor_msgs::msg::dds_::LaserScan_/TypeHashNotSupported"
    )
    assert data_key(
        3, "detections", "vision_msgs/msg/Detection2DArray", RosDistro.JAZZY, "/r1"
    ) == (f"3/r1/detections/vision_msgs::msg::dds_::Detection2DArray_/{DETS_HASH}")
    for bad_topic in ("", "/", "//a", "/a//b", "/a/*", "/a b"):
        with pytest.raises(ValueError):
            data_key(0, bad_topic, TWIST, RosDistro.JAZZY)
    with pytest.raises(ValueError):
        data_key(-1, "/cmd_vel", TWIST, RosDistro.JAZZY)


def test_fully_qualified_names() -> None:
    assert fully_qualified("/cmd_vel") == "/cmd_vel"
    assert fully_qualified("cmd_vel", "/robot1") == "/robot1/cmd_vel"
    assert fully_qualified("cmd_vel", "/robot1/") == "/robot1/cmd_vel"
    assert fully_qualified("/abs/topic", "/ignored") == "/abs/topic"


def test_attachment_layout() -> None:
    gid = bytes(range(16))
    stamp = 1_700_000_000_123_456_789
    encoded = Attachment(1, stamp, gid).encode()
    assert len(encoded) == ATTACHMENT_SIZE == 33
    assert encoded == (1).to_bytes(8, "little") + stamp.to_bytes(8, "little") + b"\x10" + gid
    assert Attachment.decode(encoded) == Attachment(1, stamp, gid)
    assert Attachment.decode(memoryview(encoded)).sequence_number == 1
    negative = Attachment(-5, 0, gid).encode()
    assert Attachment.decode(negative).sequence_number == -5


def test_attachment_garbage_raises_decode_error_only() -> None:
    good = Attachment(42, 7, gid_for("x")).encode()
    bad = [b"", good[:-1], good + b"\x00", good[:16] + b"\x18" + good[17:], os.urandom(41)]
    bad += [os.urandom(n) for n in range(0, 64) if n != 33]
    for payload in bad:
        with pytest.raises(DecodeError):
            Attachment.decode(payload)
    # Any 33 bytes with the 0x10 length byte is an attachment.
    for _ in range(50):
        raw = bytearray(os.urandom(33))
        raw[16] = 0x10
        assert Attachment.decode(bytes(raw)).encode() == bytes(raw)


def test_attachment_refuses_to_build_what_it_cannot_encode() -> None:
    with pytest.raises(ValueError):
        Attachment(1, 0, b"short")
    with pytest.raises(ValueError):
        Attachment(2**63, 0, bytes(16))


def test_gid_is_16_stable_bytes_per_name() -> None:
    token = "@ros2_lv/0/abc/0/1/MP/%/%/node/%cmd_vel/t/h/::,10:,:,:,,"
    assert len(gid_for(token)) == 16
    assert gid_for(token) == gid_for(token)
    assert gid_for(token) != gid_for(token + "x")


def test_gid_is_rmw_zenohs_xxh3_128_low64_then_high64() -> None:
    # xxHash's own sanity vector for XXH3-128 of no bytes (seed 0): low64 0x6001C324468D497F,
    # high64 0x99AA06D3014798D8. rmw_zenoh copies low64 then high64, each little-endian.
    assert gid_for("") == bytes.fromhex("7f498d4624c30160d8984701d306aa99")
    token = "@ros2_lv/0/abc/0/1/MP/%/%/node/%cmd_vel/t/h/::,10:,:,:,,"
    h = xxhash.xxh3_128_intdigest(token.encode())
    low, high = h & (2**64 - 1), h >> 64
    assert gid_for(token) == low.to_bytes(8, "little") + high.to_bytes(8, "little")


def _parse_qos(text: str) -> list[list[str]]:
    """The checks rmw_zenoh's keyexpr_to_qos makes before reading the numbers."""
    parts = text.split(":")
    assert len(parts) == 6
    fields = [parts[0:1], parts[1:2], *(p.split(",") for p in parts[2:])]
    assert [len(f) for f in fields] == [1, 1, 2, 2, 2, 3]
    for field in fields:
        for value in field:
            assert value == "" or value.isdigit()
    return fields


@pytest.mark.parametrize(
    ("qos", "expected"),
    [
        (DEFAULT_QOS, "::,10:,:,:,,"),
        (RosQoS(depth=10), "::,10:,:,:,,"),
        (RosQoS(depth=42), "::,:,:,:,,"),
        (SENSOR_DATA_QOS, "2::,5:,:,:,,"),
        (RosQoS(durability=Durability.TRANSIENT_LOCAL, depth=1), ":1:,1:,:,:,,"),
        (RosQoS(history=History.KEEP_ALL), "::2,10:,:,:,,"),
        (RosQoS(reliability=Reliability.BEST_EFFORT, depth=1), "2::,1:,:,:,,"),
        (RosQoS(deadline_ns=1_500_000_000), "::,10:1,500000000:,:,,"),
        (RosQoS(lifespan_ns=2_000_000_000), "::,10:,:2,0:,,"),
        (
            RosQoS(liveliness=Liveliness.MANUAL_BY_TOPIC, liveliness_lease_ns=3_000_000_001),
            "::,10:,:,:3,3,1",
        ),
    ],
)
def test_qos_strings(qos: RosQoS, expected: str) -> None:
    assert qos_string(qos) == expected
    _parse_qos(expected)


def test_qos_refuses_negative_values() -> None:
    with pytest.raises(ValueError):
        RosQoS(depth=-1)
    with pytest.raises(ValueError):
        RosQoS(deadline_ns=-1)


def test_mangle() -> None:
    assert mangle("/") == "%"
    assert mangle("/cmd_vel") == "%cmd_vel"
    assert mangle("/robot1/cmd_vel") == "%robot1%cmd_vel"
    assert mangle("talker") == "talker"


def test_node_token() -> None:
    assert node_token(0, ZID, 3, "/", "zstack_bridge") == (
        f"@ros2_lv/0/{ZID}/3/3/NN/%/%/zstack_bridge"
    )
    assert node_token(5, ZID, 0, "/robot1", "bridge", enclave="/secure") == (
        f"@ros2_lv/5/{ZID}/0/0/NN/%secure/%robot1/bridge"
    )
    for bad in ({"namespace": ""}, {"node": ""}, {"zid": ""}, {"zid": "a/b"}, {"node": "a*"}):
        with pytest.raises(ValueError):
            node_token(**(NODE | bad))


@pytest.mark.parametrize(
    ("distro", "hash_chunk"),
    [(RosDistro.HUMBLE, "TypeHashNotSupported"), (RosDistro.JAZZY, TWIST_HASH)],
)
def test_endpoint_tokens(distro: RosDistro, hash_chunk: str) -> None:
    bridge = {"node": "zstack_bridge", "distro": distro}
    publisher = _endpoint("MP", eid=1, topic="/cmd_vel", **bridge)
    assert publisher == (
        f"@ros2_lv/0/{ZID}/0/1/MP/%/%/zstack_bridge/%cmd_vel/"
        f"geometry_msgs::msg::dds_::Twist_/{hash_chunk}/::,10:,:,:,,"
    )
    subscriber = _endpoint("MS", eid=2, topic="/robot1/cmd_vel", qos=SENSOR_DATA_QOS, **bridge)
    assert subscriber == (
        f"@ros2_lv/0/{ZID}/0/2/MS/%/%/zstack_bridge/%robot1%cmd_vel/"
        f"geometry_msgs::msg::dds_::Twist_/{hash_chunk}/2::,5:,:,:,,"
    )
    for token in (publisher, subscriber):
        chunks = token.split("/")
        assert len(chunks) == 13
        assert all(chunks)
        _parse_qos(chunks[12])


def test_endpoint_token_joins_a_relative_topic_to_the_namespace() -> None:
    token = _endpoint(
        "MP",
        nid=1,
        eid=4,
        namespace="/robot1",
        node="bridge",
        topic="detections",
        ros_type="vision_msgs/msg/Detection2DArray",
        distro=RosDistro.KILTED,
    )
    assert token.split("/")[7:12] == [
        "%robot1",
        "bridge",
        "%robot1%detections",
        "vision_msgs::msg::dds_::Detection2DArray_",
        DETS_HASH,
    ]


def test_endpoint_token_refuses_other_kinds() -> None:
    with pytest.raises(ValueError):
        _endpoint("SS")  # type: ignore[arg-type]
