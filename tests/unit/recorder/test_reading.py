"""Reading recordings: ours (also cut short), a bag rosbags wrote, and files that are not
readable recordings, each refused with one line."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as BagWriter

from common.counters import Counters
from common.errors import DecodeError, RecordingError
from common.messages import Frame, Header, LaserScan, Twist
from rosmsg.convert import cdr_encode, scan_to_ros
from rosmsg.distro import RosDistro
from rosmsg.images import frame_to_image
from rosmsg.typestore import typestore_for
from services.recorder.channels import Translator
from services.recorder.contract import RecorderSettings
from services.recorder.reading import Recording, check_playable, decode_input
from services.recorder.writer import McapFile, QueuedRecorder
from services.ros2.contract import Ros2Settings
from tests.polling import wait_for

D = RosDistro.JAZZY
SETTINGS = RecorderSettings(chunk_size_kb=16, flush_period_s=60.0)


def _frame(seq: int) -> Frame:
    header = Header(stamp_ns=1_700_000_000 * 10**9 + seq * 10**8, frame_id="cam", seq=seq,
                    source="sim")  # fmt: skip
    pixels = np.random.default_rng(seq).integers(0, 255, 64 * 48 * 3, dtype=np.uint8)
    return Frame(header=header, encoding="bgr8", width=64, height=48, data=pixels.tobytes())


def _write(path: Path, frames: int, *, finish: bool) -> McapFile:
    out = McapFile(path, SETTINGS)
    translator = Translator(Ros2Settings(), "front")
    for seq in range(1, frames + 1):
        frame = _frame(seq)
        for entry in translator.entries("stack/camera/front/frame", frame):
            out.add(entry, frame.header.stamp_ns + 1000)
    if finish:
        out.close()
    return out


def test_our_recording_plays_back_as_the_frames_we_wrote(tmp_path: Path) -> None:
    _write(tmp_path / "r.mcap", 5, finish=True)
    with Recording(tmp_path / "r.mcap") as rec:
        records = list(rec.records())
        assert not rec.truncated
        assert rec.scan() == [("/camera/rgb/image_raw", "cdr", "sensor_msgs/msg/Image")]
    frames = [decode_input(r, D, source="replay", seq=r.message.sequence) for r in records]
    assert [f.header.seq for f in frames if f] == [1, 2, 3, 4, 5]
    assert frames[2] is not None and frames[2].data == _frame(3).data


def test_a_recording_cut_short_is_read_up_to_its_last_full_chunk(tmp_path: Path) -> None:
    live = _write(tmp_path / "live.mcap", 12, finish=False)  # as a SIGKILL leaves it
    on_disk = (tmp_path / "live.mcap").read_bytes()
    assert len(on_disk) == live.bytes_written  # every finished chunk is on disk already
    (tmp_path / "cut.mcap").write_bytes(on_disk[: len(on_disk) - 100])  # and a torn chunk
    for name in ("live.mcap", "cut.mcap"):
        with Recording(tmp_path / name) as rec:
            seqs = [r.message.sequence for r in rec.records()]
            assert rec.truncated
        assert seqs == list(range(1, len(seqs) + 1)) and len(seqs) >= 6


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"hello, not a recording at all", "not an MCAP file"),
        (b"", "not an MCAP file"),
    ],
)
def test_a_file_that_is_not_mcap_is_refused(tmp_path: Path, content: bytes, message: str) -> None:
    (tmp_path / "x.mcap").write_bytes(content)
    with pytest.raises(RecordingError, match=message):
        Recording(tmp_path / "x.mcap")
    with pytest.raises(RecordingError, match="cannot read"):
        Recording(tmp_path / "missing.mcap")


def test_a_corrupt_chunk_is_refused_with_one_line(tmp_path: Path) -> None:
    _write(tmp_path / "r.mcap", 12, finish=True)
    data = bytearray((tmp_path / "r.mcap").read_bytes())
    data[3000:3400] = bytes(400)  # inside the first chunk
    (tmp_path / "bad.mcap").write_bytes(data)
    with Recording(tmp_path / "bad.mcap") as rec, pytest.raises(RecordingError) as err:
        list(rec.records())
    assert "corrupt MCAP" in str(err.value) and "\n" not in str(err.value)


def test_unknown_schemas_and_missing_topics_are_refused() -> None:
    channels = [("/cam", "cdr", "my_msgs/msg/Image"), ("/scan", "cdr", "sensor_msgs/msg/LaserScan"),
                ("stack/x", "json", "")]  # fmt: skip
    check_playable(channels, None)  # the scan can be played
    check_playable(channels, ["/scan"])
    with pytest.raises(RecordingError, match="unknown schema 'my_msgs/msg/Image'"):
        check_playable(channels, ["/cam"])
    with pytest.raises(RecordingError, match="no topic '/nope'"):
        check_playable(channels, ["/nope"])
    with pytest.raises(RecordingError, match="nothing to play"):
        check_playable(channels[:1], None)


def test_a_ros2_bag_written_by_rosbags_decodes_to_frames_and_scans(tmp_path: Path) -> None:
    store = typestore_for(D)
    frame = _frame(1)
    scan = LaserScan(header=frame.header, angle_min=-1.0, angle_increment=0.01, range_min=0.1,
                     range_max=8.0, ranges=np.full(201, 2.5, np.float32))  # fmt: skip
    with BagWriter(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        image_conn = bag.add_connection("/oakd/rgb/image_raw", "sensor_msgs/msg/Image",
                                        typestore=store)  # fmt: skip
        scan_conn = bag.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
        t = frame.header.stamp_ns
        bag.write(image_conn, t, cdr_encode(D, "sensor_msgs/msg/Image", frame_to_image(D, frame)))
        bag.write(scan_conn, t, cdr_encode(D, "sensor_msgs/msg/LaserScan", scan_to_ros(D, scan)))
    with Recording(tmp_path / "bag") as rec:  # the folder: its one .mcap file
        decoded = [decode_input(r, D, source="replay", seq=i + 1) for i, r in
                   enumerate(rec.records())]  # fmt: skip
    image, ros_scan = decoded
    assert isinstance(image, Frame) and image.data == frame.data and image.header.seq == 1
    assert isinstance(ros_scan, LaserScan) and ros_scan.ranges.tolist() == [2.5] * 201


def test_bad_cdr_in_a_recording_is_a_decode_error(tmp_path: Path) -> None:
    with (tmp_path / "r.mcap").open("wb") as f:
        w = Writer(f)
        w.start("ros2", "test")
        schema = w.register_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        channel = w.register_channel("/image", "cdr", schema)
        w.add_message(channel, log_time=1, data=b"\x00\x01garbage", publish_time=1)
        w.finish()  # type: ignore[no-untyped-call]
    with Recording(tmp_path / "r.mcap") as rec:
        (record,) = list(rec.records())
    with pytest.raises(DecodeError):
        decode_input(record, D, source="replay", seq=1)


def test_a_full_queue_drops_and_counts_and_never_blocks(tmp_path: Path) -> None:
    gate, entered = threading.Event(), threading.Event()

    def slow_decode(payload: bytes) -> Twist:
        entered.set()
        gate.wait(10)  # the writer thread is busy until the test lets it go
        return Twist.decode(payload)

    counters = Counters()
    settings = RecorderSettings(queue_size=2)
    rec = QueuedRecorder(McapFile(tmp_path / "q.mcap", settings),
                         Translator(Ros2Settings(), "front"), settings, counters)  # fmt: skip
    twist = Twist(header=Header(stamp_ns=10**18, frame_id="base", seq=1, source="controller"))
    payload = twist.encode()
    assert rec.offer("stack/controller/cmd_vel", payload, 1, slow_decode)
    assert entered.wait(10)  # the writer holds the first one
    offered = [rec.offer("stack/controller/cmd_vel", payload, 2, slow_decode) for _ in range(5)]
    assert offered == [True, True, False, False, False]
    gate.set()
    rec.close()
    assert counters.snapshot() == {"received": 6, "dropped": 3, "written": 3}
    with Recording(tmp_path / "q.mcap") as reader:
        topics = [r.channel.topic for r in reader.records()]
    assert topics.count("/cmd_vel") == 3 and not reader.truncated


def test_at_a_stop_the_queue_is_written_within_its_budget_and_the_rest_dropped(
    tmp_path: Path,
) -> None:
    entered, gate = threading.Event(), threading.Event()

    def slow_decode(payload: bytes) -> Twist:
        entered.set()
        gate.wait(10)  # the writer is busy with the first one until the close
        return Twist.decode(payload)

    counters = Counters()
    settings = RecorderSettings(queue_size=10)
    rec = QueuedRecorder(McapFile(tmp_path / "b.mcap", settings),
                         Translator(Ros2Settings(), "front"), settings, counters)  # fmt: skip
    twist = Twist(header=Header(stamp_ns=10**18, frame_id="base", seq=1, source="controller"))
    payload = twist.encode()
    assert rec.offer("stack/controller/cmd_vel", payload, 1, slow_decode)
    assert entered.wait(10)
    for _ in range(4):
        assert rec.offer("stack/controller/cmd_vel", payload, 2, slow_decode)
    # No time left: what is still queued once the close begins is dropped, the file finished.
    closing = threading.Thread(target=rec.close, kwargs={"budget_s": 0.0})
    closing.start()
    wait_for(rec._closing.is_set, 10, "the close to begin")
    gate.set()
    closing.join(10)
    assert not closing.is_alive()
    assert counters.snapshot() == {"received": 5, "dropped": 4, "written": 1}
    with Recording(tmp_path / "b.mcap") as reader:
        topics = [r.channel.topic for r in reader.records()]
    assert topics.count("/cmd_vel") == 1 and not reader.truncated


def test_a_writer_that_fails_says_so_and_closing_does_not_hang(tmp_path: Path) -> None:
    def broken(payload: bytes) -> Twist:
        raise RuntimeError("disk on fire")

    counters = Counters()
    settings = RecorderSettings(queue_size=1)
    rec = QueuedRecorder(McapFile(tmp_path / "f.mcap", settings),
                         Translator(Ros2Settings(), "front"), settings, counters)  # fmt: skip
    for _ in range(3):
        rec.offer("stack/controller/cmd_vel", b"", 1, broken)
    rec.close()
    assert isinstance(rec.failed, RuntimeError)


def test_each_cameras_frames_play_back_onto_its_own_key(tmp_path: Path) -> None:
    from services.camera.contract import CameraSettings
    from services.recorder.play import Played, frame_keys, one_pass
    from stack.config import Config

    config = Config(cameras=(("rear", CameraSettings()),))
    out = McapFile(tmp_path / "two.mcap", SETTINGS)
    translator = Translator(config.ros2, config.stack.camera)
    for seq in range(1, 5):
        frame = _frame(seq)
        camera = "front" if seq % 2 else "rear"
        for entry in translator.entries(f"stack/camera/{camera}/frame", frame):
            out.add(entry, frame.header.stamp_ns + 1000)
    out.close()
    assert frame_keys(config) == {
        "/camera/rgb/image_raw": "stack/camera/front/frame",
        "/camera/rgb/image_raw/compressed": "stack/camera/front/frame",
        "/rear/camera/rgb/image_raw": "stack/camera/rear/frame",
        "/rear/camera/rgb/image_raw/compressed": "stack/camera/rear/frame",
    }
    put: list[tuple[str, int]] = []
    topics = ["/camera/rgb/image_raw", "/rear/camera/rgb/image_raw"]
    one_pass(config, tmp_path / "two.mcap", topics, 1000.0,
             lambda key, b: put.append((key, Frame.decode(b).header.seq)),
             threading.Event(), Played())  # fmt: skip
    assert put == [("stack/camera/front/frame", 1), ("stack/camera/rear/frame", 2),
                   ("stack/camera/front/frame", 3), ("stack/camera/rear/frame", 4)]  # fmt: skip
    # A one-camera stack plays every image topic onto its camera, as before.
    put.clear()
    one_pass(Config(), tmp_path / "two.mcap", topics, 1000.0,
             lambda key, b: put.append((key, Frame.decode(b).header.seq)),
             threading.Event(), Played())  # fmt: skip
    assert {key for key, _ in put} == {"stack/camera/front/frame"} and len(put) == 4
