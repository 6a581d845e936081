"""The live view, watched as the Foxglove app watches it: a ``foxglove.sdk.v1`` WebSocket client
(the ``websockets`` package) on the default stack (simulator, detector, controller, metrics,
viewer), decoding what it receives with google.protobuf from the advertised schemas."""

from __future__ import annotations

import asyncio
import base64
import json
import time
from typing import Any

import cv2
import numpy as np
import pytest
import websockets

from common.ports import holders
from services.viewer import channels as ch
from tests.foxglove_client import SUBPROTOCOL, decode_channel_message, split_message_frame
from tests.integration.conftest import Stack, wait_for
from tools.launch import free_port

pytestmark = pytest.mark.integration

SERVICES = ["sim", "detector", "controller", "metrics", "viewer"]
TOPICS = {ch.IMAGE, ch.ANNOTATIONS, ch.SCAN, ch.TF, ch.SCENE, ch.CMD_VEL, ch.CONTROLLER, ch.METRICS}
WATCH_S = 90.0  # the detector's first frames are slow on a loaded 2-core machine


def _is_person(text: str) -> bool:
    return text.removeprefix("LOCKED ").startswith("person ")


async def _watch(port: int, deadline: float) -> dict[str, Any]:
    """Connect, read the advertised channels, subscribe to all of them, and collect one
    decoded message of each topic, an image and annotations that hold a person's box."""
    got: dict[str, Any] = {}
    async with websockets.connect(
        f"ws://127.0.0.1:{port}",
        subprotocols=[SUBPROTOCOL],
        max_size=None,  # type: ignore[list-item]
    ) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        advertised: dict[str, dict[str, Any]] = {}
        while not advertised.keys() >= TOPICS:
            msg = json.loads(await asyncio.wait_for(ws.recv(), deadline - time.monotonic()))
            if msg["op"] == "serverInfo":
                got["server"] = msg["name"]
            if msg["op"] == "advertise":
                advertised.update({c["topic"]: c for c in msg["channels"]})
        got["advertised"] = advertised
        subs = {i: advertised[t] for i, t in enumerate(sorted(TOPICS), start=1)}
        await ws.send(json.dumps({
            "op": "subscribe",
            "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in subs.items()],
        }))  # fmt: skip
        image_stamps: set[str] = set()
        while not (got.keys() >= TOPICS and "person" in got):
            frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
            if isinstance(frame, str):
                continue  # status or re-advertisement
            sub_id, _log_time, payload = split_message_frame(frame)
            channel = subs[sub_id]
            msg = decode_channel_message(channel, payload)
            got[channel["topic"]] = msg
            if channel["topic"] == ch.IMAGE:
                image_stamps.add(msg["timestamp"])
            if channel["topic"] == ch.ANNOTATIONS:
                people = [t for t in msg.get("texts", []) if _is_person(t["text"])]
                if people and msg["timestamp"] in image_stamps:  # the image it was made on
                    got["person"] = (msg, people[0])
    return got


def test_foxglove_client_sees_the_camera_and_a_person(make_stack) -> None:  # type: ignore[no-untyped-def]
    port, relay = free_port(), free_port()
    while relay == port:  # two asks a moment apart may be handed the same free port
        relay = free_port()
    stack: Stack = make_stack(
        supervisor={"services": SERVICES},
        # The Foxglove server behind the front on the relay port the config names.
        viewer={"port": port, "relay_port": relay, "image_rate_hz": 10.0},
        sim={"wait_for": ["detector", "controller"]},
        # As the default stack: it locks onto the person (by box height: no_laser, as every
        # test stack says, needs it in follow mode).
        controller={"mode": "follow", "distance_source": "box"},
    )
    stack.wait_ready(set(SERVICES))
    # Garbage on a key the viewer reads is counted, and the view goes on.
    stack.session.put(stack.keys.frame("front"), b"\x00garbage")
    try:
        got = asyncio.run(_watch(port, time.monotonic() + WATCH_S))
    except TimeoutError:
        pytest.fail(f"no person seen through the live view in {WATCH_S:.0f} s:\n{stack.log()}")
    assert got["server"] == "zenoh-yolo-stack"
    assert any("services.viewer" in command for _, command in holders(relay)), holders(relay)
    adv = got["advertised"]
    assert adv[ch.IMAGE]["schemaName"] == "foxglove.CompressedImage"
    assert adv[ch.ANNOTATIONS]["schemaName"] == "foxglove.ImageAnnotations"
    assert (adv[ch.METRICS]["encoding"], adv[ch.METRICS]["schemaEncoding"]) == (
        "json",
        "jsonschema",
    )

    image = got[ch.IMAGE]
    assert image["format"] == "jpeg"
    pixels = cv2.imdecode(np.frombuffer(base64.b64decode(image["data"]), np.uint8), 1)
    assert pixels is not None and pixels.shape == (480, 640, 3)  # the simulator's camera

    annotations, text = got["person"]
    i = annotations["texts"].index(text)
    box = annotations["points"][i]["points"]
    xs, ys = [p.get("x", 0.0) for p in box], [p.get("y", 0.0) for p in box]
    assert 0 <= min(xs) < max(xs) <= 640 and 0 <= min(ys) < max(ys) <= 480
    assert got[ch.SCAN]["frameId"] == "base_link" and got[ch.SCAN]["ranges"]
    assert "linear" in got[ch.CMD_VEL] and "state" in got[ch.CONTROLLER]
    assert "fps" in got[ch.METRICS]

    def viewer_counted_the_garbage() -> bool:
        m = stack.metrics()
        return bool(m and m["counters"].get("viewer.bad_input", 0) >= 1)

    wait_for(viewer_counted_the_garbage, 15, "the viewer's bad_input in the metrics")
    assert stack.stop() == 0, stack.log()  # the viewer, too, exits cleanly on Ctrl-C
