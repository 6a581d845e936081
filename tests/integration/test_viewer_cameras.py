"""The live view with two cameras: a real viewer process, a ``foxglove.sdk.v1`` client (the
``websockets`` package, as in test_viewer.py), and this test as the cameras and the detector,
putting each camera's frames and detections on its own keys. Each camera's images and
annotations must arrive on that camera's own channels, and never on the other's. The front
camera has depth (issue 32): its depth image, the 3D boxes of its detections with depth and the
transform from the robot to it (by its announced mounting) arrive too."""

from __future__ import annotations

import asyncio
import base64
import json
import math
import threading
import time
from typing import Any

import cv2
import numpy as np
import pytest
import websockets

from common.boxes import Boxes
from common.frames import image_to_frame
from common.messages import DepthFrame, Detections, Header
from perception.depth import COLUMNS
from services.viewer import channels as ch
from tests.foxglove_client import SUBPROTOCOL, decode_channel_message, split_message_frame
from tests.integration.conftest import Stack
from tools.launch import free_port

pytestmark = pytest.mark.integration

WATCH_S = 60.0
#: A channel that brought nothing for this long is subscribed again (s).
RESUBSCRIBE_S = 3.0
# Each camera's picture size and the one class its detector "sees": told apart on arrival.
CAMERAS = {"front": ((64, 48), "person"), "rear": ((96, 32), "dog")}
TOPICS = {
    name: ch.camera_topics("front", name) for name in CAMERAS
}  # front: /camera/image, rear: /camera/rear/image
# The front camera's depth: everything 2.5 m away; its mounting; its one detection's 3D columns.
DEPTH_MM = 2500
MOUNT = {"mount_x_m": 0.2, "mount_y_m": 0.0, "mount_height_m": 0.5, "frame_id": "front_optical"}
CENTRE_SIZE = {"x_m": 0.1, "y_m": -0.2, "z_m": 2.5, "size_x_m": 0.5, "size_y_m": 1.0,
               "size_z_m": 0.3}  # fmt: skip
DEPTH_COLUMNS = {"distance_m": math.dist((0, 0, 0), (0.1, -0.2, 2.5)), **CENTRE_SIZE}
DEPTH_TOPICS = (ch.depth_topic("front", "front"), ch.BOXES_3D, ch.TF)


def _publish(stack: Stack, stop: threading.Event) -> None:
    """Both cameras at 10 Hz, each frame followed by the detections made on it (a box of its
    class); the front camera announced with depth and its depth image put with each frame, its
    detections with the depth columns."""
    tokens = [
        stack.announce(
            name, width=w, height=h, **({"depth": True, **MOUNT} if name == "front" else {})
        )
        for name, ((w, h), _) in CAMERAS.items()
    ]
    seq = 0
    while not stop.wait(0.1):
        seq += 1
        for name, ((w, h), label) in CAMERAS.items():
            header = Header(stamp_ns=time.time_ns(), frame_id=name, seq=seq, source="test")
            frame = image_to_frame(np.full((h, w, 3), 128, np.uint8), header)
            columns: dict[str, np.ndarray] = {}
            if name == "front":
                columns = {c: np.array([DEPTH_COLUMNS[c]], np.float32) for c in COLUMNS}
                depth = DepthFrame(
                    header=header, encoding="16UC1", width=w, height=h,
                    data=np.full((h, w), DEPTH_MM, "<u2").tobytes(),
                    fx=60.0, fy=60.0, cx=w / 2, cy=h / 2,
                )  # fmt: skip
                stack.session.put(stack.keys.depth(name), depth.encode())
            dets = Detections(
                header=header, image_width=w, image_height=h, class_names=(label,),
                boxes=Boxes(xyxy=np.array([(2, 2, w / 2, h / 2)], np.float32),
                            scores=np.array([0.9], np.float32),
                            class_ids=np.zeros(1, np.int32), columns=columns),
            )  # fmt: skip
            stack.session.put(stack.keys.frame(name), frame.encode())
            stack.session.put(stack.keys.detections(name), dets.encode())
    for token in tokens:
        token.undeclare()


async def _watch(port: int, deadline: float) -> dict[str, list[dict[str, Any]]]:
    """Subscribe to every camera's image and annotations; collect what arrives on each until
    every one of them has brought two messages."""
    wanted = {t for pair in TOPICS.values() for t in pair} | set(DEPTH_TOPICS)
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
        subs: dict[int, dict[str, Any]] = {}

        async def subscribe(topics: list[str]) -> None:
            new = {len(subs) + k: advertised[t] for k, t in enumerate(sorted(topics), start=1)}
            subs.update(new)
            await ws.send(json.dumps({
                "op": "subscribe",
                "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in new.items()],
            }))  # fmt: skip

        await subscribe(sorted(wanted))
        while not all(len(v) >= 2 for v in got.values()):
            # As a client should: a subscription the server did not take (a loaded CI run: the
            # viewer said "attempted to subscribe to unknown channel" and nothing came for
            # 60 s) is asked again, on the channel as now advertised, after a quiet while.
            left = deadline - time.monotonic()
            try:
                frame = await asyncio.wait_for(ws.recv(), min(left, RESUBSCRIBE_S))
            except TimeoutError:
                if left <= RESUBSCRIBE_S:
                    raise
                await subscribe([t for t, v in got.items() if not v])
                continue
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    advertised.update({c["topic"]: c for c in msg["channels"]})
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
    depth_topic, boxes_topic, tf_topic = DEPTH_TOPICS
    for image in got[depth_topic]:  # the front camera's, as put, in millimetres
        assert (image["encoding"], image["width"], image["height"]) == ("16UC1", 64, 48)
        pixels = np.frombuffer(base64.b64decode(image["data"]), "<u2")
        assert (pixels == DEPTH_MM).all()
    for update in got[boxes_topic]:
        [entity] = update["entities"]
        assert (entity["id"], entity["frameId"]) == ("boxes/front", "front_optical")
        [cube] = entity["cubes"]
        assert cube["pose"]["position"]["z"] == pytest.approx(2.5)
        assert [t["text"] for t in entity["texts"]] == ["person 2.51 m"]
    mounts = {t["childFrameId"]: t for m in got[tf_topic] for t in m["transforms"]}
    assert set(mounts) == {"front_optical", "camera"}  # rear announces the default frame id
    front = mounts["front_optical"]
    assert front["parentFrameId"] == "base_link"
    assert front["translation"]["z"] == pytest.approx(0.5)
    assert stack.stop() == 0, stack.log()
