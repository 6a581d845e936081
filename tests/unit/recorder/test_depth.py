"""Depth in a recording (issue 32): the recorder writes each camera's DepthFrames as
``sensor_msgs/Image`` + ``CameraInfo`` (read back by mcap_ros2, a decoder we did not write) and
the camera announcements as JSON; ``play`` puts the depth images back on ``Keys.depth`` with the
header of the colour frame they were captured with, and announces the camera with depth and its
recorded mounting. Recorded here through the real Recorder on a MemoryHub."""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from common.bus import QoS
from common.camera_announce import CameraAnnouncements
from common.clock import wall_ns
from common.errors import RecordingError
from common.keys import Keys
from common.memory_bus import MemoryHub
from common.messages import CameraAnnouncement, DepthFrame, Frame, Header
from common.node import Node
from services.camera.contract import CameraSettings
from services.recorder.channels import Translator
from services.recorder.contract import RecorderSettings
from services.recorder.depth_ros import depth_topics
from services.recorder.play import (
    ANNOUNCED_SOURCE,
    Played,
    announce_played,
    one_pass,
    playable_topics,
    recorded_cameras,
)
from services.recorder.reading import Recording
from services.recorder.service import SERVICE, Recorder
from services.recorder.writer import McapFile
from stack.config import Config
from tests.polling import wait_for
from tests.unit.heard import heard_cameras

CONFIG = Config(
    recorder=RecorderSettings(chunk_size_kb=16, flush_period_s=0.05),
    cameras=(("rear", CameraSettings(mount_yaw_deg=180.0)),),
)
KEYS = Keys(CONFIG.stack.prefix)
FRONT = CONFIG.stack.camera
FRAMES = 4
DEPTH = "/camera/aligned_depth_to_color/image_raw"
DEPTH_INFO = "/camera/aligned_depth_to_color/camera_info"


def _header(seq: int, frame_id: str) -> Header:
    # Captured a few ms before it is heard: within the lag a replay keeps (timing.py).
    return Header(stamp_ns=time.time_ns() - 3_000_000, frame_id=frame_id, seq=seq, source="sim")


def _frame(header: Header) -> Frame:
    return Frame(header=header, encoding="bgr8", width=8, height=6, data=bytes(8 * 6 * 3))


def _depth(header: Header, encoding: str) -> DepthFrame:
    """A 4x3 depth image (half the colour frame's size), every reading a different one; the
    32FC1 one with a hole (NaN)."""
    if encoding == "16UC1":
        data = (np.arange(12, dtype=np.uint16) * 250 + 500 + header.seq).tobytes()
        limits = {"range_min_m": 0.3, "range_max_m": 6.0}
    else:
        metres = np.arange(12, dtype=np.float32) * 0.5 + 1.0 + header.seq
        metres[5] = np.nan
        data, limits = metres.tobytes(), {}
    return DepthFrame(header=header, encoding=encoding, width=4, height=3, data=data,
                      fx=4.1, fy=4.2, cx=2.05, cy=1.45, **limits)  # fmt: skip


def _record(path: Path) -> dict[str, list[tuple[Frame, DepthFrame]]]:
    """Record both cameras with depth through the Recorder on a MemoryHub: front 16UC1 (its
    announcement with depth and a mounting), rear 32FC1 (announced as configured). Depth comes
    before its colour frame every other frame, as it may on the bus."""
    hub = MemoryHub()
    sent: dict[str, list[tuple[Frame, DepthFrame]]] = {FRONT: [], "rear": []}
    with Node(SERVICE, CONFIG, bus=hub.join(SERVICE)) as node:
        recorder = Recorder(node, path, CONFIG).listen(node)
        sim = hub.join("sim")
        with CameraAnnouncements(sim, KEYS, "sim") as announcements:
            front = CameraSettings(rate_hz=10.0, hfov_deg=70.0, frame_id="front_optical",
                                   mount_height_m=0.42, mount_x_m=0.1, mount_y_m=-0.05)  # fmt: skip
            announcements.announce(FRONT, front, depth=True)
            rear = CameraSettings(rate_hz=10.0, mount_yaw_deg=180.0, frame_id="rear_optical")
            announcements.announce("rear", rear)
            for seq in range(1, FRAMES + 1):
                for camera, encoding in ((FRONT, "16UC1"), ("rear", "32FC1")):
                    header = _header(seq, f"{camera}_optical")
                    frame, depth = _frame(header), _depth(header, encoding)
                    sent[camera].append((frame, depth))
                    puts = [(KEYS.frame(camera), frame), (KEYS.depth(camera), depth)]
                    for key, msg in puts if seq % 2 else puts[::-1]:
                        sim.publisher(key, QoS.SENSOR).put(msg.encode())
                # Frames apart in time, as a camera sends them (the recorder stamps arrival
                # on the wall clock).
                sent_at = wall_ns()
                wait_for(lambda t=sent_at: wall_ns() - t >= 2_000_000, 5, "2 ms to pass")
        recorder.close()
        assert node.counters.get("dropped") == 0 and node.counters.get("bad_input") == 0
    return sent


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:  # type: ignore[type-arg]
    path = tmp_path_factory.mktemp("depth") / "r.mcap"
    return path, _record(path)


def test_depth_is_an_image_and_its_camera_info_that_a_foreign_reader_decodes(
    recording: tuple[Path, dict],  # type: ignore[type-arg]
) -> None:
    path, sent = recording
    front, rear = depth_topics(CONFIG.ros2, FRONT, FRONT), depth_topics(CONFIG.ros2, FRONT, "rear")
    # The bridge's topics (ros2.depth_topic, ros2.depth_info_topic), the rear's under its
    # namespace.
    assert (front.image, front.info) == (DEPTH, DEPTH_INFO)
    assert (rear.image, rear.info) == ("/rear" + DEPTH, "/rear" + DEPTH_INFO)
    seen: dict[str, list[object]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        everything = [front.image, front.info, rear.image, rear.info]
        for _, channel, message, ros in reader.iter_decoded_messages(topics=everything):
            seen.setdefault(channel.topic, []).append(ros)
            if channel.topic == front.image:
                assert channel.metadata["range_max_m"] == "6.0"
                assert message.publish_time == _stamp(ros)  # the capture stamp
    topics = (front.image, front.info, rear.image, rear.info)
    assert {t: len(v) for t, v in seen.items()} == dict.fromkeys(topics, FRAMES)
    image, info = seen[front.image][0], seen[front.info][0]
    first = sent[FRONT][0][1]
    assert (image.encoding, image.width, image.height) == ("16UC1", 4, 3)  # type: ignore[attr-defined]
    assert bytes(image.data) == first.data  # type: ignore[attr-defined]
    assert list(info.k) == pytest.approx([4.1, 0, 2.05, 0, 4.2, 1.45, 0, 0, 1])  # type: ignore[attr-defined]
    assert seen[rear.image][0].encoding == "32FC1"  # type: ignore[attr-defined]


def _stamp(ros: object) -> int:
    stamp = ros.header.stamp  # type: ignore[attr-defined]
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


def test_play_puts_each_depth_image_on_its_key_with_its_colour_frames_header(
    recording: tuple[Path, dict],  # type: ignore[type-arg]
) -> None:
    path, sent = recording
    topics = playable_topics(path, None)
    assert DEPTH in topics and DEPTH_INFO in topics
    put: list[tuple[str, bytes]] = []
    played = Played()
    one_pass(CONFIG, path, topics, 50.0, lambda k, b: put.append((k, b)), threading.Event(),
             played)  # fmt: skip
    assert (played.frames, played.depths, played.bad_input) == (2 * FRAMES, 2 * FRAMES, 0)
    for camera in (FRONT, "rear"):
        frames = {f.header.seq: f for f in (Frame.decode(b) for k, b in put
                                           if k == KEYS.frame(camera))}  # fmt: skip
        depths = [DepthFrame.decode(b) for k, b in put if k == KEYS.depth(camera)]
        assert [d.header.seq for d in depths] == list(range(1, FRAMES + 1))
        for depth, (_, original) in zip(depths, sent[camera], strict=True):
            # Paired as recorded: the played colour frame's header, restamped to now.
            assert depth.header == frames[depth.header.seq].header
            assert depth.header.source == "replay"
            assert depth.header.stamp_ns != original.header.stamp_ns
            assert depth == dataclasses.replace(original, header=depth.header)  # NaN: same bytes


def test_the_played_camera_is_announced_with_depth_and_its_recorded_mounting(
    recording: tuple[Path, dict],  # type: ignore[type-arg]
) -> None:
    path, _ = recording
    recorded = recorded_cameras(CONFIG, path, playable_topics(path, None))
    assert {c: r.depth for c, r in recorded.items()} == {FRONT: True, "rear": True}
    hub = MemoryHub()
    heard = heard_cameras(hub, KEYS)
    with CameraAnnouncements(hub.join("play"), KEYS, ANNOUNCED_SOURCE) as announcements:
        announce_played(CONFIG, announcements, recorded, rate=1.0)
        front, rear = heard.current()[FRONT], heard.current()["rear"]
    assert (front.depth, front.mount_height_m, front.mount_x_m, front.mount_y_m) == (
        True, 0.42, 0.1, -0.05,
    )  # fmt: skip
    assert front.hfov_deg == 70.0 and front.source == "play"
    assert (rear.depth, rear.mount_height_m, rear.mount_yaw_deg) == (True, 0.0, 180.0)
    # Colour frames alone chosen: no depth announced.
    colour = ["/camera/rgb/image_raw", "/rear/camera/rgb/image_raw"]
    assert not any(r.depth for r in recorded_cameras(CONFIG, path, colour).values())
    # Depth chosen alone brings the CameraInfo along.
    assert playable_topics(path, [DEPTH]) == [DEPTH, DEPTH_INFO, "/rear" + DEPTH_INFO]


def _bad_file(path: Path) -> list[DepthFrame]:
    """Three depth images of the front camera: good, garbage CDR, good; and a rear one with no
    CameraInfo before it."""
    out = McapFile(path, RecorderSettings(chunk_size_kb=16))
    translator = Translator(CONFIG.ros2, FRONT)
    good = []
    for seq in (1, 2, 3):
        header = Header(stamp_ns=10**18 + seq * 10**8, frame_id="f", seq=seq, source="sim")
        depth = _depth(header, "16UC1")
        info, image = translator.entries(KEYS.depth(FRONT), depth)
        if seq == 2:
            image = dataclasses.replace(image, data=image.data[: len(image.data) // 2])
        else:
            good.append(depth)
        out.add(info, header.stamp_ns)
        out.add(image, header.stamp_ns)
    _, rear = translator.entries(KEYS.depth("rear"), _depth(_header(1, "r"), "32FC1"))
    out.add(rear, 10**18 + 5 * 10**8)
    out.close()
    return good


def test_bad_depth_entries_are_skipped_counted_and_said_in_one_line(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    good = _bad_file(tmp_path / "bad.mcap")
    put: list[tuple[str, bytes]] = []
    played = Played()
    caplog.set_level(logging.WARNING, "recorder")
    one_pass(CONFIG, tmp_path / "bad.mcap", playable_topics(tmp_path / "bad.mcap", None), 1000.0,
             lambda k, b: put.append((k, b)), threading.Event(), played)  # fmt: skip
    assert (played.depths, played.bad_input) == (2, 2)
    assert [DepthFrame.decode(b).data for _, b in put] == [d.data for d in good]
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and all("\n" not in line for line in lines), lines
    assert DEPTH in lines[0] and "not valid CDR" in lines[0]
    assert f"no CameraInfo on /rear{DEPTH_INFO}" in lines[1]


def test_a_truncated_recording_plays_its_depth_up_to_the_cut_then_says_so(
    tmp_path: Path,
) -> None:
    # Six depth images of 20 kB of noise (LZ4 cannot shrink it), each over a 16 kB chunk: a
    # chunk each; cut halfway.
    noise = np.random.default_rng(1).integers(0, 65535, 100 * 100, np.uint16).tobytes()
    out = McapFile(tmp_path / "r.mcap", RecorderSettings(chunk_size_kb=16))
    translator = Translator(CONFIG.ros2, FRONT)
    for seq in range(1, 7):
        header = Header(stamp_ns=10**18 + seq * 10**8, frame_id="f", seq=seq, source="sim")
        depth = DepthFrame(header=header, encoding="16UC1", width=100, height=100,
                           data=noise, fx=50.0, fy=50.0, cx=50.0, cy=50.0)  # fmt: skip
        for entry in translator.entries(KEYS.depth(FRONT), depth):
            out.add(entry, header.stamp_ns)
    out.close()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((tmp_path / "r.mcap").read_bytes()[: 3 * 21_000])
    played = Played()
    topics = playable_topics(tmp_path / "r.mcap", None)
    with pytest.raises(RecordingError, match=r"truncated .* 0 frames, [1-5] depth images"):
        one_pass(CONFIG, cut, topics, 1000.0, lambda k, b: None, threading.Event(), played)
    assert 0 < played.depths < 6 and played.truncated


def test_a_file_cut_before_anything_playable_says_it_is_truncated(tmp_path: Path) -> None:
    # The first chunk holds only announcements (as a recording's first flush may); cut there.
    out = McapFile(tmp_path / "r.mcap", RecorderSettings(chunk_size_kb=16))
    translator = Translator(CONFIG.ros2, FRONT)
    said = CameraAnnouncement(camera=FRONT, rate_hz=10.0, frame_id="x" * 100, depth=True)
    announce_key = KEYS.camera_announcements_of(FRONT).removesuffix("/*")
    while out.bytes_written < 16 * 1024:  # until the first chunk is on disk
        for entry in translator.entries(announce_key, said):
            out.add(entry, 10**18)
    first_chunk = out.bytes_written
    for entry in translator.entries(KEYS.depth(FRONT), _depth(_header(1, "f"), "16UC1")):
        out.add(entry, 10**18)
    out.close()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((tmp_path / "r.mcap").read_bytes()[:first_chunk])
    with pytest.raises(RecordingError, match=r"^nothing to play: .*; .* is truncated after \d+ "):
        playable_topics(cut, None)


def test_detections_with_depth_are_also_3d_boxes_on_the_bridges_topic() -> None:
    from common.boxes import Boxes
    from common.messages import Detections
    from perception.depth import COLUMNS
    from rosmsg.convert import cdr_decode

    columns = {name: np.array([1.0, np.nan], np.float32) for name in COLUMNS}
    columns["z_m"] = np.array([2.5, np.nan], np.float32)
    dets = Detections(
        header=_header(3, "front_optical"), image_width=8, image_height=6,
        class_names=("person", "chair"),
        boxes=Boxes(xyxy=np.array([[0, 0, 4, 6], [4, 0, 8, 6]], np.float32),
                    scores=np.array([0.9, 0.8], np.float32), class_ids=np.array([0, 56], np.int32),
                    columns=columns),
    )  # fmt: skip
    translator = Translator(CONFIG.ros2, FRONT)
    flat, boxes_3d, js = translator.entries(KEYS.detections("rear"), dets)
    assert (flat.channel.topic, boxes_3d.channel.topic) == (
        "/rear/detections",
        "/rear/detections_3d",
    )
    ros = cdr_decode(CONFIG.ros2.distro, "vision_msgs/msg/Detection3DArray", boxes_3d.data)
    # The chair's distance is unknown: no 3D box is made up for it.
    assert [d.results[0].hypothesis.class_id for d in ros.detections] == ["person"]
    assert ros.detections[0].bbox.center.position.z == pytest.approx(2.5)
    assert ros.header.frame_id == "front_optical" and js.channel.message_encoding == "json"
    # Without depth: the 2D boxes and the JSON only, as before.
    plain = dataclasses.replace(dets, boxes=dataclasses.replace(dets.boxes, columns={}))
    assert len(translator.entries(KEYS.detections("rear"), plain)) == 2


def test_a_garbage_announcement_is_counted_as_bad_input_not_recorded(tmp_path: Path) -> None:
    hub = MemoryHub()
    with Node(SERVICE, CONFIG, bus=hub.join(SERVICE)) as node:
        recorder = Recorder(node, tmp_path / "r.mcap", CONFIG).listen(node)
        token = hub.join("sim").declare_token(KEYS.camera_announcement(FRONT, "bm90LWEtbWVzc2FnZQ"))
        token.undeclare()  # its going is not recorded
        recorder.close()
        assert (node.counters.get("received"), node.counters.get("bad_input")) == (1, 1)
    with Recording(tmp_path / "r.mcap") as rec:
        assert [r.stack_type for r in rec.records()] == []


def test_a_ros2_bag_of_an_rgbd_camera_plays_its_depth(tmp_path: Path) -> None:
    # A bag rosbags wrote, as `ros2 bag record` of a RealSense driver makes one: colour, the
    # aligned depth and its camera_info (the bridge's default depth topics), and a second depth
    # camera of another robot (no configured camera's topic: its CameraInfo beside it).
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as BagWriter

    from rosmsg.convert import cdr_encode
    from rosmsg.images import frame_to_image
    from rosmsg.typestore import typestore_for
    from services.recorder.depth_ros import depth_to_ros

    d = CONFIG.ros2.distro
    store = typestore_for(d)
    other = "/robot2/depth/image_raw"
    sent = []
    with BagWriter(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        conns = {
            topic: bag.add_connection(topic, ros_type, typestore=store)
            for topic, ros_type in (
                ("/camera/color/image_raw", "sensor_msgs/msg/Image"),
                (DEPTH_INFO, "sensor_msgs/msg/CameraInfo"),
                (DEPTH, "sensor_msgs/msg/Image"),
                ("/robot2/depth/camera_info", "sensor_msgs/msg/CameraInfo"),
                (other, "sensor_msgs/msg/Image"),
            )
        }
        for seq in (1, 2):
            header = Header(stamp_ns=10**18 + seq * 10**8, frame_id="cam", seq=0, source="bag")
            depth = _depth(header, "16UC1")
            sent.append(depth)
            info, image = depth_to_ros(d, depth)
            t = header.stamp_ns
            colour = frame_to_image(d, _frame(header))
            bag.write(
                conns["/camera/color/image_raw"], t, cdr_encode(d, "sensor_msgs/msg/Image", colour)
            )
            for depth_topic, info_topic in (
                (DEPTH, DEPTH_INFO),
                (other, "/robot2/depth/camera_info"),
            ):
                bag.write(conns[info_topic], t, cdr_encode(d, "sensor_msgs/msg/CameraInfo", info))
                bag.write(conns[depth_topic], t, cdr_encode(d, "sensor_msgs/msg/Image", image))
    topics = playable_topics(tmp_path / "bag", None)
    put: list[tuple[str, bytes]] = []
    played = Played()
    one_pass(Config(), tmp_path / "bag", topics, 1000.0, lambda k, b: put.append((k, b)),
             threading.Event(), played)  # fmt: skip
    assert (played.frames, played.depths, played.bad_input) == (2, 4, 0)
    depths = [DepthFrame.decode(b) for k, b in put if k == KEYS.depth(FRONT)]
    assert [d.data for d in depths] == [s.data for s in sent for _ in (DEPTH, other)]
    assert {(d.fx, d.cy) for d in depths} == {(4.1, 1.45)}
    recorded = recorded_cameras(Config(), tmp_path / "bag", topics)
    assert recorded[FRONT].depth and recorded[FRONT].announced is None
