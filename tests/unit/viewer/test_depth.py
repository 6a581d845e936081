"""Depth in the live view (issue 32): the depth image, the 3D boxes of detections with depth and
the transforms from the robot to each camera, decoded as Foxglove would; and the viewer hearing
a camera's depth only while it is announced with depth and a client watches it."""

from __future__ import annotations

import base64
import math
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import foxglove
import numpy as np
import pytest
from mcap.reader import make_reader

from common.boxes import Boxes
from common.bus import QoS
from common.clock import FakeClock
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, DepthFrame, Detections, Header
from common.node import Node
from perception.depth import COLUMNS, Mounting, to_robot
from services.viewer import channels as ch
from services.viewer import depth
from services.viewer.channels import Channels
from services.viewer.service import Viewer
from stack.config import Config
from tests.foxglove_client import decode_protobuf

HEADER = Header(stamp_ns=1_700_000_000_250_000_000, frame_id="front_optical", seq=7, source="sim")


def _decode(msg: Any) -> dict[str, Any]:
    schema = type(msg).get_schema()
    return decode_protobuf(schema.name, schema.data, msg.encode())


def _depth_frame(encoding: str, values: np.ndarray, header: Header = HEADER) -> DepthFrame:
    h, w = values.shape
    data = values.astype("<u2" if encoding == "16UC1" else "<f4").tobytes()
    return DepthFrame(
        header=header, encoding=encoding, width=w, height=h, data=data,
        fx=50.0, fy=50.0, cx=w / 2, cy=h / 2, range_min_m=0.2, range_max_m=10.0,
    )  # fmt: skip


def _pixels(msg: dict[str, Any]) -> np.ndarray:
    raw = np.frombuffer(base64.b64decode(msg["data"]), "<u2")
    return raw.reshape(msg["height"], msg["width"])


def test_a_depth_image_is_16uc1_millimetres_no_reading_zero() -> None:
    mm = np.array([[0, 1500, 2000, 12000], [100, 800, 65535, 3000]], np.uint16)
    msg = _decode(depth.depth_image(_depth_frame("16UC1", mm), max_width=0))
    assert (msg["encoding"], msg["width"], msg["height"], msg["step"]) == ("16UC1", 4, 2, 8)
    assert msg["frameId"] == "front_optical" and msg["timestamp"] == "2023-11-14T22:13:20.250Z"
    # No reading, and readings outside the stated 0.2..10 m, are 0.
    assert _pixels(msg).tolist() == [[0, 1500, 2000, 0], [0, 800, 0, 3000]]
    metres = np.array([[np.nan, 1.2345, np.inf, 0.0], [2.0, -1.0, 9.9994, 0.5]], np.float32)
    msg = _decode(depth.depth_image(_depth_frame("32FC1", metres), max_width=0))
    assert _pixels(msg).tolist() == [[0, 1234, 0, 0], [2000, 0, 9999, 500]]


def test_a_depth_image_is_scaled_by_nearest_neighbour() -> None:
    # 1 m, then 5 m from column 63 on: halved, one pixel sees both; a blend (3 m) would be a
    # reading nobody measured.
    mm = np.hstack([np.full((64, 63), 1000), np.full((64, 65), 5000)]).astype(np.uint16)
    msg = _decode(depth.depth_image(_depth_frame("16UC1", mm), max_width=64))
    pixels = _pixels(msg)
    assert pixels.shape == (32, 64)
    assert set(np.unique(pixels).tolist()) == {1000, 5000}
    assert (pixels[:, :31] == 1000).all() and (pixels[:, 32:] == 5000).all()


def _rotate(q: dict[str, float], v: np.ndarray) -> np.ndarray:
    """``v`` rotated by the quaternion ``q`` (protobuf's JSON omits zero fields)."""
    x, y, z, w = (q.get(k, 0.0) for k in "xyzw")
    u = np.array([x, y, z])
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def _announcement(camera: str, **fields: Any) -> CameraAnnouncement:
    return CameraAnnouncement(camera=camera, rate_hz=10.0, source="test", **fields)


@pytest.mark.parametrize("yaw", [0.0, 90.0, 180.0, -30.0])
def test_each_camera_stands_where_its_mounting_says(yaw: float) -> None:
    cameras = {
        "front": _announcement("front", frame_id="front_optical", mount_yaw_deg=yaw,
                               mount_x_m=0.2, mount_y_m=-0.1, mount_height_m=0.45, depth=True),
        "rear": _announcement("rear"),  # nothing known: at the base's centre, on the floor
    }  # fmt: skip
    msg = _decode(depth.camera_transforms(cameras, HEADER.stamp_ns))
    front, rear = msg["transforms"]
    assert (front["parentFrameId"], front["childFrameId"]) == ("base_link", "front_optical")
    assert rear["childFrameId"] == "rear_optical"  # no frame id announced
    # Two cameras left at one frame id (the default "camera") would share a frame: not so.
    twins = {"a": _announcement("a", frame_id="camera"), "b": _announcement("b", frame_id="camera")}
    assert depth.optical_frames(twins) == {"a": "a_optical", "b": "b_optical"}
    t = front["translation"]
    origin = np.array([t.get("x", 0.0), t.get("y", 0.0), t.get("z", 0.0)])
    # Points of the optical frame (x right, y down, z forward) land where to_robot puts them.
    points = np.array([[0.0, 0.0, 1.0], [0.5, -0.3, 2.0], [-1.0, 0.2, 4.0]], np.float32)
    mount = Mounting(x_m=0.2, y_m=-0.1, height_m=0.45, yaw_deg=yaw)
    expected = np.stack(to_robot(points[:, 0], points[:, 1], points[:, 2], mount), axis=1)
    got = np.array([origin + _rotate(front["rotation"], p.astype(np.float64)) for p in points])
    np.testing.assert_allclose(got, expected, atol=1e-6)


def _detections(track_ids: list[int] | None = None) -> Detections:
    """A person at 2 m (centre x 0.5 m, y -0.2 m), a dog of unknown depth (NaN)."""
    nan = float("nan")
    rows = {
        "distance_m": [math.sqrt(0.25 + 0.04 + 4.0), nan],
        "x_m": [0.5, nan], "y_m": [-0.2, nan], "z_m": [2.0, nan],
        "size_x_m": [0.6, nan], "size_y_m": [1.7, nan], "size_z_m": [0.3, nan],
    }  # fmt: skip
    return Detections(
        header=HEADER,
        image_width=640,
        image_height=480,
        boxes=Boxes(
            xyxy=np.array([[300, 100, 400, 400], [10, 10, 50, 50]], np.float32),
            scores=np.array([0.9, 0.8], np.float32),
            class_ids=np.array([0, 16], np.int32),
            track_ids=None if track_ids is None else np.array(track_ids, np.int32),
            columns={name: np.array(rows[name], np.float32) for name in COLUMNS},
        ),
        class_names=("person", "dog"),
    )


def test_each_detection_with_depth_is_a_cube_labelled_with_its_distance() -> None:
    dets = _detections()
    assert depth.has_depth(dets)
    msg = _decode(depth.boxes_scene(dets, "front", "front_optical", -1, lifetime_s=1.5))
    [entity] = msg["entities"]
    assert (entity["id"], entity["frameId"], entity["frameLocked"]) == (
        "boxes/front", "front_optical", True,
    )  # fmt: skip
    assert entity["lifetime"] == "1.500s"
    [cube] = entity["cubes"]  # the dog's depth is unknown: no cube, never a made-up one
    position, size = cube["pose"]["position"], cube["size"]
    assert (position["x"], position["z"]) == pytest.approx((0.5, 2.0))
    assert position["y"] == pytest.approx(-0.2)
    assert (size["x"], size["y"], size["z"]) == pytest.approx((0.6, 1.7, 0.3))
    [text] = entity["texts"]
    assert text["text"] == "person 2.07 m"
    assert text["pose"]["position"]["y"] == pytest.approx(-0.2 - 1.7 / 2)  # on its top
    assert cube["color"]["a"] == pytest.approx(depth.BOX_ALPHA)


def test_the_target_is_red() -> None:
    msg = _decode(depth.boxes_scene(_detections([4, 5]), "front", "f", 4, lifetime_s=1.0))
    [entity] = msg["entities"]
    assert entity["texts"][0]["text"] == "LOCKED person 2.07 m"
    colour = entity["cubes"][0]["color"]
    assert (colour["r"], colour.get("g", 0.0)) == pytest.approx(depth.LOCKED_RGB[:2])


def test_detections_without_depth_have_no_boxes() -> None:
    dets = _detections()
    plain = replace(dets, boxes=replace(dets.boxes, columns={}))
    assert not depth.has_depth(plain)


# -- the viewer in-process: a MemoryHub, a FakeClock, an MCAP file as the client ---------------
class Rig:
    """A viewer on a hub, its channels recorded (an MCAP sink: every channel is watched)
    when ``watched``, and the test as the sources and the detector."""

    def __init__(self, path: Path, watched: bool) -> None:
        self.config = Config()
        self.hub = MemoryHub()
        self.clock = FakeClock()
        self.node = Node("viewer", self.config, bus=self.hub.join("viewer"), clock=self.clock)
        context = foxglove.Context()
        self.path = path
        self.mcap = foxglove.open_mcap(path, context=context) if watched else None
        cameras = list(self.config.all_cameras)
        self.camera = cameras[0]
        self.viewer = Viewer(
            self.node, Channels(context, cameras), self.config, self.node.subscribe,
            clock=self.clock,
        )  # fmt: skip
        self.probe = self.hub.join("test")

    def put(self, key: str, payload: bytes) -> None:
        self.probe.publisher(key, QoS.TELEMETRY).put(payload)

    def recorded(self) -> dict[str, list[dict[str, Any]]]:
        """Every message written, by topic, decoded (closes the recording)."""
        assert self.mcap is not None
        self.mcap.close()
        out: dict[str, list[dict[str, Any]]] = {}
        with self.path.open("rb") as f:
            for schema, channel, message in make_reader(f).iter_messages():
                assert schema is not None
                if channel.message_encoding == "protobuf":
                    decoded = decode_protobuf(schema.name, schema.data, message.data)
                    out.setdefault(channel.topic, []).append(decoded)
        return out

    def close(self) -> None:
        if self.viewer.depth is not None:
            self.viewer.depth.close()
        self.probe.close()
        self.node.close()


@pytest.fixture
def rigs(tmp_path: Path) -> Iterator[list[Rig]]:
    made: list[Rig] = []
    yield made
    for rig in made:
        rig.close()


def test_the_viewer_shows_depth_boxes_and_mountings(tmp_path: Path, rigs: list[Rig]) -> None:
    rig = Rig(tmp_path / "view.mcap", watched=True)
    rigs.append(rig)
    viewer, cam = rig.viewer, rig.camera
    key = rig.node.keys.depth(cam)
    frame = _depth_frame("16UC1", np.full((48, 64), 2500, np.uint16))
    viewer.send_depth()
    assert viewer.depth is not None and viewer.depth.subscribed() == set()  # not announced yet
    viewer.set_announced({cam: _announcement(cam, frame_id="front_optical", mount_height_m=0.4)})
    viewer.send_depth()
    assert viewer.depth.subscribed() == set()  # announced without depth: no depth heard
    viewer.set_announced({
        cam: _announcement(cam, frame_id="front_optical", mount_height_m=0.4, depth=True),
        "ghost": _announcement("ghost", depth=True),  # not one of the viewer's cameras
    })  # fmt: skip
    viewer.send_depth()
    assert viewer.depth.subscribed() == {cam}
    for _ in range(3):  # three come before the encoder's turn: the newest is sent
        rig.put(key, frame.encode())
    rig.put(key, b"garbage")
    viewer.send_depth()  # the garbage was the newest: counted as bad input, nothing sent
    rig.put(key, frame.encode())
    viewer.send_depth()
    viewer.cameras[cam].on_detections(_detections().encode())
    rig.clock.advance(0.01)  # sooner than image_rate_hz allows: not sent
    viewer.cameras[cam].on_detections(replace(_detections(), class_names=("cat", "dog")).encode())
    counters = dict(viewer.tally.counters.snapshot())
    got = rig.recorded()
    [image] = got[ch.depth_topic(cam, cam)]
    assert (image["encoding"], image["width"], image["height"]) == ("16UC1", 64, 48)
    assert (_pixels(image) == 2500).all()
    [boxes] = got[ch.BOXES_3D]
    assert [t["text"] for t in boxes["entities"][0]["texts"]] == ["person 2.07 m"]
    # The camera's transform at each turn of the encoder once announced (the ghost's never).
    mounts = [t for m in got[ch.TF] for t in m["transforms"]]
    assert len(mounts) == 4 and {t["childFrameId"] for t in mounts} == {"front_optical"}
    assert mounts[-1]["translation"]["z"] == pytest.approx(0.4)
    assert counters["depth_in"] == 5 and counters["depth_out"] == 1, counters
    assert counters["bad_input"] == 1, counters


def test_no_client_no_depth_heard(tmp_path: Path, rigs: list[Rig]) -> None:
    rig = Rig(tmp_path / "unused.mcap", watched=False)
    rigs.append(rig)
    rig.viewer.set_announced({rig.camera: _announcement(rig.camera, depth=True)})
    rig.viewer.send_depth()
    assert rig.viewer.depth is not None and rig.viewer.depth.subscribed() == set()
    rig.put(rig.node.keys.depth(rig.camera), b"whatever")
    assert "depth_in" not in dict(rig.viewer.tally.counters.snapshot())
