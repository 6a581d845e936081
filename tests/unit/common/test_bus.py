"""The publisher says what its payload is: a subscriber sees Zenoh's encoding on each sample."""

from __future__ import annotations

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
