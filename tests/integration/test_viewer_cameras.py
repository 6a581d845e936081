"""The live view with two cameras: a real viewer process, a ``foxglove.sdk.v1`` client (the
``websockets`` package, as in test_viewer.py), and this test as the cameras and the detector,
putting each camera's frames and detections on its own keys. Each camera's images and
annotations must arrive on that camera's own channels, and never on the other's."""

from __future__ import annotations

import asyncio
import base64
import json
import threading
import time
from typing import Any

import cv2
import numpy as np
import pytest
import websockets

from services.viewer import channels as ch
from tests.foxglove_client import SUBPROTOCOL, decode_channel_message, split_message_frame
from tests.integration.conftest import Stack, publish_cameras
from tools.launch import free_port

pytestmark = pytest.mark.integration

WATCH_S = 60.0
# Each camera's picture size and the one class its detector "sees": told apart on arrival.
CAMERAS = {"front": ((64, 48), "person"), "rear": ((96, 32), "dog")}
TOPICS = {
    name: ch.camera_topics("front", name) for name in CAMERAS
}  # front: /camera/image, rear: /camera/rear/image


def _publish(stack: Stack, stop: threading.Event) -> None:
    """Both cameras at 10 Hz, each frame followed by the detections made on it."""
    publish_cameras(
        stack, stop, CAMERAS, fill=128, box=lambda w, h: (2, 2, w / 2, h / 2), score=0.9
    )


async def _watch(port: int, deadline: float) -> dict[str, list[dict[str, Any]]]:
    """Subscribe to every camera's image and annotations; collect what arrives on each until
    every one of them has brought two messages."""
    wanted = {t for pair in TOPICS.values() for t in pair}
    got: dict[str, list[dict[str, Any]]] = {t: [] for t in wanted}
    async with websockets.connect(
        f"ws://127.0.0.1:{port}",
        subprotocols=[SUBPROTOCOL],
        max_size=None,  # type: ignore[list-item]
    ) as ws:
        advertised: dict[str, dict[str, Any]] = {}
        while not advertised.keys() >= wanted:
            msg = json.loads(await asyncio.wait_for(ws.recv(), deadline - time.monotonic()))
            if msg["op"] == "advertise":
                advertised.update({c["topic"]: c for c in msg["channels"]})
        subs = {i: advertised[t] for i, t in enumerate(sorted(wanted), start=1)}
        await ws.send(json.dumps({
            "op": "subscribe",
            "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in subs.items()],
        }))  # fmt: skip
        while not all(len(v) >= 2 for v in got.values()):
            frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
            if isinstance(frame, str):
                continue
            sub_id, _log_time, payload = split_message_frame(frame)
            channel = subs[sub_id]
            got[channel["topic"]].append(decode_channel_message(channel, payload))
    return got


def test_each_camera_on_its_own_channels(make_stack) -> None:  # type: ignore[no-untyped-def]
    port = free_port()
    stack: Stack = make_stack(
        supervisor={"services": ["viewer"]},
        viewer={"port": port, "image_rate_hz": 10.0},
        **{"cameras.rear": {"mount_yaw_deg": 180.0}},
    )
    assert list(stack.config.all_cameras) == ["front", "rear"]
    stack.wait_ready({"viewer"})
    stop = threading.Event()
    threading.Thread(target=_publish, args=(stack, stop), daemon=True).start()
    try:
        got = asyncio.run(_watch(port, time.monotonic() + WATCH_S))
    except TimeoutError:
        pytest.fail(f"not every camera's channels had images in {WATCH_S:.0f} s:\n{stack.log()}")
    finally:
        stop.set()
    assert TOPICS["front"] == (ch.IMAGE, ch.ANNOTATIONS)  # the one-camera topics, unchanged
    stamps = {name: {m["timestamp"] for m in got[TOPICS[name][0]]} for name in CAMERAS}
    for name, ((w, h), label) in CAMERAS.items():
        image_topic, annotations_topic = TOPICS[name]
        for image in got[image_topic]:
            pixels = cv2.imdecode(np.frombuffer(base64.b64decode(image["data"]), np.uint8), 1)
            assert pixels.shape == (h, w, 3), (name, pixels.shape)  # this camera's, only
        for marks in got[annotations_topic]:
            texts = [t["text"] for t in marks["texts"]]
            assert texts and all(t.startswith(f"{label} ") for t in texts), (name, texts)
        # Each camera's annotations were made on that camera's images (the same stamps).
        marked = {m["timestamp"] for m in got[annotations_topic]}
        (other,) = set(CAMERAS) - {name}
        assert marked & stamps[name] and not marked & stamps[other], (name, marked, stamps)
    assert stack.stop() == 0, stack.log()
