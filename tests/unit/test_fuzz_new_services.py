"""Property-based fuzzing of the viewer's and the recorder's subscription handlers, in the
style of test_fuzz_handlers.py: the service runs for real (in a thread, on a Zenoh session
that reaches nobody) and the test hands each callback generated payloads itself.

The viewer decodes in Zenoh's callback (``Node.subscribe``): ``bad_input`` grows by exactly
one for each payload the decoder rejects, and what it takes becomes Foxglove messages without
raising. The recorder's callbacks only queue the raw bytes; decoding and the JSON and CDR
conversion happen on its writer thread, so there a payload is "rejected" when it cannot be
converted: the writer must survive every payload, count each once (``written`` or
``bad_input``), and leave a file the ``mcap`` reader reads from end to end.
"""

from __future__ import annotations

import json
import socket
import threading
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from common.codec import Message
from common.errors import DecodeError
from common.messages import ControllerStatus, Detections, Frame, GroundTruth, LaserScan, Twist
from common.node import Node
from common.settings import Config, ViewerSettings
from services.recorder import service as recorder
from services.recorder.channels import JSON, Translator
from services.viewer import service as viewer
from services.viewer.convert import MAX_STAMP_S
from tests.unit.fuzz import (
    EDGE_STAMPS_NS,
    FakeSample,
    RecordingSession,
    edge_stamped,
    fuzz,
    message_payloads,
    samples,
)
from tests.unit.fuzz_serving import fuzz_handler, serving, wait_until

EXAMPLES = 30  # per subscription: the viewer's 6 and the recorder's 8
WRITER_S = 10.0  # the most one payload may wait for the recorder's writer thread
#: The messages whose stamp the viewer turns into a Foxglove timestamp in Zenoh's callback.
STAMPED_IN_CALLBACK = (LaserScan, GroundTruth)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def past_foxglove(stamp_ns: int) -> bool:
    return stamp_ns // 1_000_000_000 > MAX_STAMP_S


def test_the_viewers_handlers_and_encoder(monkeypatch: pytest.MonkeyPatch) -> None:
    made: list[viewer.Viewer] = []

    class Recorded(viewer.Viewer):
        def __init__(self, *args: Any, **kw: Any) -> None:
            super().__init__(*args, **kw)
            made.append(self)

    monkeypatch.setattr(viewer, "Viewer", Recorded)
    config = Config(viewer=ViewerSettings(port=free_port(), max_image_width=64))
    with serving(monkeypatch, viewer, config) as (node, (session,)):
        before = node.counters.get("frames_in")
        fed = _viewer_handler(node, session, "/frame", Frame)
        rejected = node.counters.get("bad_input.frame")
        assert node.counters.get("frames_in") - before == fed - rejected
        for part, cls in [
            ("/detections", Detections),
            ("/scan", LaserScan),
            ("/cmd_vel", Twist),
            ("/controller/status", ControllerStatus),
            ("/sim/truth", GroundTruth),
        ]:
            _viewer_handler(node, session, part, cls)
        _fuzz_the_encoder(made[0])


def _viewer_handler(node: Node, session: RecordingSession, part: str, cls: type[Message]) -> int:
    """Fuzz the one subscription on ``part``, then feed it every edge stamp: valid, so never
    bad input; past Foxglove's timestamps, counted as unshowable where the callback converts."""
    [(key, handler)] = session.handlers_of(part)
    fed = fuzz_handler(node, handler, key, cls.decode, message_payloads(cls, fresh=True), EXAMPLES)
    c = node.counters
    before = (c.get("bad_input"), c.get("unshowable"))
    for payload in edge_stamped(cls):
        handler(FakeSample(key, payload))
    past = sum(past_foxglove(at) for at in EDGE_STAMPS_NS) if cls in STAMPED_IN_CALLBACK else 0
    assert (c.get("bad_input"), c.get("unshowable")) == (before[0], before[1] + past), key
    return fed + len(EDGE_STAMPS_NS)


def _decoded(cls: type[Message], payload: bytes) -> Any:
    try:
        return cls.decode(payload)
    except DecodeError:
        return None


OUTCOMES = ("images_out", "bad_input", "unshowable")


def _sent(live: viewer.Viewer, frame: Frame, dets: Detections | None) -> str:
    """``live.send``: which one of OUTCOMES it counted."""
    c = live.node.counters
    before = {name: c.get(name) for name in OUTCOMES}
    live.send(frame, dets)
    grew = [name for name in OUTCOMES if c.get(name) != before[name]]
    assert len(grew) == 1 and c.get(grew[0]) == before[grew[0]] + 1, grew
    return grew[0]


def _fuzz_the_encoder(live: viewer.Viewer) -> None:
    """What the encoder thread does with a frame and its detections that decoded (it only
    sends while a client watches, so the test calls ``send`` itself): each pair is sent
    (``images_out``), or counted as bad input (unreadable pixels) or as unshowable (a stamp
    Foxglove cannot carry), exactly one of the three, and nothing raises. A frame stamped
    past 2106 used to kill the encoder thread (OverflowError): the edge stamps below."""
    fallback = samples(None)[Frame][0]
    seen = dict.fromkeys(OUTCOMES, 0)

    @fuzz(EXAMPLES * 2)
    @given(frame=message_payloads(Frame, fresh=True), dets=message_payloads(Detections))
    def check(frame: bytes, dets: bytes) -> None:
        seen[_sent(live, _decoded(Frame, frame) or fallback, _decoded(Detections, dets))] += 1

    check()
    assert seen["images_out"] > 0, seen
    dets = samples(None)[Detections][0]
    for payload in edge_stamped(Frame):
        frame = Frame.decode(payload)
        expected = "unshowable" if past_foxglove(frame.header.stamp_ns) else "images_out"
        assert _sent(live, frame, dets) == expected
    for payload in edge_stamped(Detections):
        boxes = Detections.decode(payload)
        expected = "unshowable" if past_foxglove(boxes.header.stamp_ns) else "images_out"
        assert _sent(live, fallback, boxes) == expected


# ---------------------------------------------------------------------------- the recorder


class _Ledger:
    """What the recorder should have done with the payloads fed so far."""

    def __init__(self) -> None:
        self.written = 0
        self.rejected = 0
        self.entries = 0  # MCAP messages: a stack message is written as one or two


def _recorded(
    node: Node, rec: recorder.Recorder, handler: Any, key: str, cls: type[Message],
    payload: bytes, ledger: _Ledger,
) -> None:  # fmt: skip
    """Feed one payload and wait for the writer to take it: it must still run, and have
    counted the payload once, as ``written`` or, if it cannot convert it, as ``bad_input``."""
    c = node.counters
    before = {name: c.get(name) for name in ("received", "written", "bad_input")}
    handler(FakeSample(key, payload))
    assert c.get("received") == before["received"] + 1
    wait_until(
        lambda: (
            rec.failed is not None
            or c.get("written") + c.get("bad_input") > before["written"] + before["bad_input"]
        ),
        f"the writer to take a payload on {key}",
        WRITER_S,
    )
    assert rec.failed is None, f"the writer thread died on {payload[:64]!r}: {rec.failed!r}"
    try:  # what the writer should make of it
        entries = Translator(node.config.ros2).entries(key, cls.decode(payload))
    except (DecodeError, ValueError):  # garbage, or a stamp no ROS Time holds (2038)
        assert c.get("bad_input") - before["bad_input"] == 1, key
        assert c.get("written") == before["written"], key
        ledger.rejected += 1
        return
    assert c.get("written") - before["written"] == 1, key
    assert c.get("bad_input") == before["bad_input"], key
    ledger.written += 1
    ledger.entries += len(entries)


def _fuzz_recorded(
    node: Node, rec: recorder.Recorder, key: str, cls: type[Message], ledger: _Ledger
) -> None:
    handler = next(h for k, h in node.session.handlers if k == key)
    concrete = key.replace("*", "fuzz")  # a sample arrives on a key, never on a wildcard

    @fuzz(EXAMPLES)
    @given(payload=message_payloads(cls, fresh=True))
    def check(payload: bytes) -> None:
        _recorded(node, rec, handler, concrete, cls, payload, ledger)

    check()
    for payload in edge_stamped(cls):
        _recorded(node, rec, handler, concrete, cls, payload, ledger)


def _read_back(path: Path) -> int:
    """Every message in the file, each decoded (CDR by its ros2msg schema, JSON as JSON)."""
    factory, count = DecoderFactory(), 0
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == JSON:
                json.loads(message.data)
            else:
                decode = factory.decoder_for(channel.message_encoding, schema)
                assert decode is not None, channel.topic
                decode(message.data)
            count += 1
        assert summary.statistics.message_count == count
    return count


def test_the_recorders_handlers_and_writer(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = tmp_path / "fuzz.mcap"
    made: list[recorder.Recorder] = []

    class Recorded(recorder.Recorder):
        def __init__(self, *args: Any, **kw: Any) -> None:
            super().__init__(*args, **kw)
            made.append(self)

    def run(config: Config, stop: threading.Event) -> int:
        return recorder.record(config, path, stop, lambda _line: None)

    monkeypatch.setattr(recorder, "Recorder", Recorded)
    config, ledger = Config(), _Ledger()
    with serving(monkeypatch, recorder, config, run=run) as (node, _sessions):
        keys = recorder.subscriptions(node.keys, config.stack.camera)
        for key, cls in keys.items():
            _fuzz_recorded(node, made[0], key, cls, ledger)
        c = node.counters
        assert c.get("dropped") == 0
        assert (c.get("written"), c.get("bad_input")) == (ledger.written, ledger.rejected)
    assert ledger.rejected > 0 and ledger.written > 0, vars(ledger)
    assert _read_back(path) == ledger.entries  # closed by the service: the file is complete
