"""The publisher says what its payload is: a subscriber sees Zenoh's encoding on each sample."""

from __future__ import annotations

import logging
import threading

import zenoh

from common.bus import Publisher, QoS
from common.messages import EStop, Header


def test_every_put_is_marked_msgpack() -> None:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    received: list[zenoh.Sample] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        received.append(sample)
        arrived.set()

    with zenoh.open(conf) as session:
        sub = session.declare_subscriber("t/estop", on_sample)
        pub = Publisher(session, "t/estop", QoS.CONTROL)
        msg = EStop(header=Header(stamp_ns=1, frame_id="", seq=0, source="t"), engaged=True)
        pub.put(msg.encode())
        assert arrived.wait(10), "the sample never arrived"
        sub.undeclare()
    assert str(received[0].encoding) == "application/msgpack"
    assert EStop.decode(received[0].payload.to_bytes()) == msg


def test_a_payload_over_the_limit_is_refused_and_reported() -> None:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    refused: list[tuple[str, int]] = []
    received: list[int] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        received.append(len(sample.payload))
        arrived.set()

    with zenoh.open(conf) as session:
        sub = session.declare_subscriber("t/frame", on_sample)
        pub = Publisher(
            session,
            "t/frame",
            QoS.SENSOR,
            max_payload_bytes=1000,
            on_refused=lambda key, size: refused.append((key, size)),
        )
        assert not pub.put(bytes(1001))
        assert pub.put(bytes(1000))
        assert arrived.wait(10), "the sample within the limit never arrived"
        sub.undeclare()
    assert refused == [("t/frame", 1001)]
    assert received == [1000]


def test_a_latest_subscription_keeps_only_the_newest_sample() -> None:
    from common.node import Latest

    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    taken: list[bytes] = []
    busy, release, done = threading.Event(), threading.Event(), threading.Event()

    def handle(payload: bytes) -> None:
        taken.append(payload)
        if payload == b"0":
            busy.set()
            release.wait(10)  # a slow handler: everything sent meanwhile waits, or not
        if payload == b"99":
            done.set()

    with zenoh.open(conf) as session:
        latest = Latest(session, "t/frame", handle, logging.getLogger("t"))
        session.put("t/frame", b"0")
        assert busy.wait(10), "the first sample never arrived"
        for n in range(1, 100):
            session.put("t/frame", str(n).encode())
        release.set()
        assert done.wait(10), f"the newest sample never arrived: {taken}"
        latest.undeclare()
        assert not latest._thread.is_alive()
    # Zenoh's ring held one sample while the handler was busy: the newest replaced the rest.
    assert taken == [b"0", b"99"]
