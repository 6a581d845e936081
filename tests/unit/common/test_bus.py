"""The publisher says what its payload is: a subscriber sees Zenoh's encoding on each sample."""

from __future__ import annotations

import logging
import threading

import zenoh

from common.messages import EStop, Header
from common.zenoh_bus import Publisher, QoS


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


def test_a_bounded_subscription_holds_up_its_sender_not_its_memory() -> None:
    from common.bus import Sample
    from common.zenoh_bus import Bounded

    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    taken: list[bytes] = []
    busy, release, done = threading.Event(), threading.Event(), threading.Event()

    def handle(sample: Sample) -> None:
        payload = sample.payload
        taken.append(payload)
        if payload == b"0":
            busy.set()
            release.wait(10)  # a slow handler: what comes meanwhile waits, two at most
        if payload == b"9":
            done.set()

    with zenoh.open(conf) as session:
        bounded = Bounded(session, "t/frame", handle, logging.getLogger("t"), depth=2)
        session.put("t/frame", b"0")
        assert busy.wait(10), "the first sample never arrived"

        def send() -> None:
            for n in range(1, 10):
                session.put("t/frame", str(n).encode())

        sender = threading.Thread(target=send)
        sender.start()
        sender.join(0.5)  # a local put delivers in the putting thread: it waits for room
        assert sender.is_alive(), "nine puts went through to a handler that took none"
        release.set()
        sender.join(10)
        assert done.wait(10), f"the last sample never arrived: {taken}"
        bounded.undeclare()
        assert not bounded._thread.is_alive()
    assert taken == [str(n).encode() for n in range(10)]  # none lost, in order
