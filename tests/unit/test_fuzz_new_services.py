"""Property-based fuzzing of the viewer's and the recorder's subscription handlers, in the
style of test_fuzz_handlers.py: the service's handler object (``Viewer``, ``Recorder``) is built
with plain collaborators and the test hands each handler generated payloads itself.

The viewer decodes in Zenoh's callback: ``bad_input`` grows by exactly one for each payload the
decoder rejects, and what it takes becomes Foxglove messages without raising. The recorder's
callbacks only queue the raw bytes; decoding and the JSON and CDR conversion happen on its
writer thread, so there a payload is "rejected" when it cannot be converted: the writer must
survive every payload, count each once (``written`` or ``bad_input``), and leave a file the
``mcap`` reader reads from end to end.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import foxglove
from hypothesis import given
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from common.codec import Message
from common.errors import DecodeError
from common.messages import ControllerStatus, Detections, Frame, GroundTruth, LaserScan, Twist
from common.node import Tally
from services.recorder import service as recorder
from services.recorder.channels import JSON, Translator
from services.recorder.contract import RecorderSettings
from services.viewer import service as viewer
from services.viewer.channels import Channels
from services.viewer.contract import ViewerSettings
from services.viewer.convert import MAX_STAMP_S
from stack.config import Config
from tests.polling import wait_for
from tests.unit.fuzz import (
    EDGE_STAMPS_NS,
    edge_stamped,
    fuzz,
    fuzz_handler,
    message_payloads,
    samples,
)

EXAMPLES = 30  # per subscription: the viewer's 6 and the recorder's 8
WRITER_S = 10.0  # the most one payload may wait for the recorder's writer thread
#: The messages whose stamp the viewer turns into a Foxglove timestamp in Zenoh's callback.
STAMPED_IN_CALLBACK = (LaserScan, GroundTruth)


def past_foxglove(stamp_ns: int) -> bool:
    return stamp_ns // 1_000_000_000 > MAX_STAMP_S


def test_the_viewers_handlers_and_encoder() -> None:
    config = Config(viewer=ViewerSettings(max_image_width=64))
    tally = Tally("viewer", config)
    live = viewer.Viewer(tally, Channels(foxglove.Context(), [config.stack.camera]), config)
    keys, camera = tally.keys, config.stack.camera
    view = live.cameras[camera]
    before = tally.counters.get("frames_in")
    fed = _viewer_handler(tally, view.on_frame, keys.frame(camera), Frame)
    rejected = tally.counters.get("bad_input.frame")
    assert tally.counters.get("frames_in") - before == fed - rejected
    for on_payload, key, cls in [
        (view.on_detections, keys.detections(camera), Detections),
        (live.on_scan, keys.scan(), LaserScan),
        (live.on_twist, keys.cmd_vel(), Twist),
        (live.on_status, keys.controller_status(), ControllerStatus),
        (live.on_truth, keys.sim_truth(), GroundTruth),
    ]:
        _viewer_handler(tally, on_payload, key, cls)
    _fuzz_the_encoder(live)


def _viewer_handler(
    tally: Tally, on_payload: Callable[[bytes], None], key: str, cls: type[Message]
) -> int:
    """Fuzz the handler of ``key``, then feed it every edge stamp: valid, so never bad input;
    past Foxglove's timestamps, counted as unshowable where the callback converts."""
    fed = fuzz_handler(
        tally, on_payload, key, cls.decode, message_payloads(cls, fresh=True), EXAMPLES
    )
    c = tally.counters
    before = (c.get("bad_input"), c.get("unshowable"))
    for payload in edge_stamped(cls):
        on_payload(payload)
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
    c = live.tally.counters
    before = {name: c.get(name) for name in OUTCOMES}
    live.cameras[live.tally.config.stack.camera].send(frame, dets)
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
    tally: Tally, rec: recorder.Recorder, key: str, cls: type[Message], payload: bytes,
    ledger: _Ledger,
) -> None:  # fmt: skip
    """Feed one payload and wait for the writer to take it: it must still run, and have
    counted the payload once, as ``written`` or, if it cannot convert it, as ``bad_input``."""
    c = tally.counters
    before = {name: c.get(name) for name in ("received", "written", "bad_input")}
    rec.on_sample(key, payload, cls.decode)
    assert c.get("received") == before["received"] + 1
    wait_for(
        lambda: (
            rec.failed is not None
            or c.get("written") + c.get("bad_input") > before["written"] + before["bad_input"]
        ),
        WRITER_S,
        f"the writer to take a payload on {key}",
        poll=0.002,
    )
    assert rec.failed is None, f"the writer thread died on {payload[:64]!r}: {rec.failed!r}"
    try:  # what the writer should make of it
        entries = Translator(tally.config.ros2, tally.config.stack.camera).entries(
            key, cls.decode(payload)
        )
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
    tally: Tally, rec: recorder.Recorder, key: str, cls: type[Message], ledger: _Ledger
) -> None:
    concrete = key.replace("*", "fuzz")  # a sample arrives on a key, never on a wildcard

    @fuzz(EXAMPLES)
    @given(payload=message_payloads(cls, fresh=True))
    def check(payload: bytes) -> None:
        _recorded(tally, rec, concrete, cls, payload, ledger)

    check()
    for payload in edge_stamped(cls):
        _recorded(tally, rec, concrete, cls, payload, ledger)


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


def test_the_recorders_handlers_and_writer(tmp_path: Path) -> None:
    path = tmp_path / "fuzz.mcap"
    # The writer takes what is queued every flush_period_s / 2 at most: at the shortest period
    # each payload waits 25 ms at most for it, not 100 ms.
    config, ledger = Config(recorder=RecorderSettings(flush_period_s=0.05)), _Ledger()
    tally = Tally(recorder.SERVICE, config)
    with recorder.Recorder(tally, path, config) as rec:
        keys = recorder.subscriptions(tally.keys, list(config.all_cameras))
        for key, cls in keys.items():
            _fuzz_recorded(tally, rec, key, cls, ledger)
        c = tally.counters
        assert c.get("dropped") == 0
        assert (c.get("written"), c.get("bad_input")) == (ledger.written, ledger.rejected)
    assert ledger.rejected > 0 and ledger.written > 0, vars(ledger)
    assert _read_back(path) == ledger.entries  # closed by the recorder: the file is complete
