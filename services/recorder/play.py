"""Playing a recording back: its frames, depth images and scans, for the stack's own keys, at
their original timing (times 1/rate), restamped to now (timing.py), as the camera or the
simulator would publish them. The detector and the controller then run on recorded data. No
zenoh here: ``service.play`` opens the session and publishes what :func:`one_pass` hands it.

The file is read once to check it (reading.py) before anything is published. Each frame keeps
its recorded sequence number (the MCAP message's ``sequence``, our recorder writes the stack
header's ``seq``; a ROS 2 bag's count otherwise), so that detections made on the replay can be
matched with the recorded ones (compare.py); its source is ``replay``. Under the secure profile
the player joins as the ``recorder`` principal, which may publish frames and scans.

With several cameras each camera's frames go back on its own key: an image topic is the camera
whose ROS 2 topic it is (``ros2.camera_namespace``, as the recorder wrote it and the bridge
maps it, :func:`frame_keys`); an image topic of no configured camera (a bag from another
robot) plays as the first camera's, as with one camera.

Depth images (an Image on a depth topic, depth_ros.py) go back on their camera's depth key
(``Keys.depth``), each with the intrinsics of the last CameraInfo beside it, with the header of
the colour frame they were recorded with: the same sequence number, frame id and new stamp
(timing.py restamps by capture stamp), so that the detector pairs them as it did live. A depth
image with no CameraInfo before it, or one that does not decode, is skipped and counted with
one line, as any bad message.

Each camera whose frames are played is announced while the play lasts (CameraAnnouncement,
common/camera_announce.py): the size and frame id of its first recorded frame, the rate it
was recorded at times the play's speed (its configured rate when the recording cannot tell:
one frame), ``depth`` when its depth images are played too, its mounting and field of view as
its source announced them when the recording holds that announcement (the recorder records
them), else from its config (:func:`recorded_cameras`, :func:`announce_played`).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.camera_announce import CameraAnnouncements
from common.clock import BOOT_ID, now
from common.errors import DecodeError, RecordingError, one_line
from common.keys import Keys
from common.messages import CameraAnnouncement, DepthFrame, Frame, Header, LaserScan
from rosmsg.depth import CAMERA_INFO
from rosmsg.distro import RosDistro
from services.recorder.depth_ros import depth_topics, is_depth_topic, sibling_info_topic
from services.recorder.reading import (
    PLAYABLE,
    Input,
    Record,
    Recording,
    check_playable,
    decode_depth,
    decode_info,
    decode_input,
    input_kind,
)
from services.recorder.timing import Schedule
from services.ros2.contract import camera_topics
from stack.config import Config

log = logging.getLogger("recorder")

SOURCE = "replay"
#: What the player says it is in the announcements of the cameras it plays.
ANNOUNCED_SOURCE = "play"


@dataclass(slots=True)
class Played:
    frames: int = 0
    depths: int = 0
    scans: int = 0
    bad_input: int = 0
    passes: int = 0
    truncated: bool = False


def playable_topics(path: Path, topics: Sequence[str] | None) -> list[str]:
    """The topics to play from ``path`` (all frames, depth images and scans when ``topics``
    is None), and the CameraInfo beside each depth image topic, after reading the whole file
    once; RecordingError for a file that cannot be played."""
    with Recording(path) as rec:
        channels = rec.scan()
    try:
        check_playable(channels, topics)
    except RecordingError as exc:
        if not rec.truncated:
            raise
        # What is missing may be in the part that was lost: say both.
        raise RecordingError(
            f"{exc}; {path} is truncated after {rec.count} messages (no end after its last "
            "full chunk)"
        ) from exc
    chosen = (
        list(topics)
        if topics is not None
        else [topic for topic, enc, schema in channels if enc == "cdr" and schema in PLAYABLE]
    )
    # A depth image's intrinsics are on a CameraInfo topic (which, depends on the config):
    # every CameraInfo goes along with depth (they are small).
    infos = {topic for topic, _, schema in channels if schema == CAMERA_INFO}
    depth = any(is_depth_topic(t) for t in chosen)
    return chosen + sorted(infos - set(chosen) if depth else ())


def info_topics(config: Config) -> dict[str, str]:
    """The CameraInfo topic of each configured camera's depth image topic (another depth topic
    has its CameraInfo beside it: :func:`info_topic_of`)."""
    first = config.stack.camera
    return {
        t.image: t.info for t in (depth_topics(config.ros2, first, c) for c in config.all_cameras)
    }


def info_topic_of(infos: dict[str, str], depth_topic: str) -> str:
    return infos.get(depth_topic) or sibling_info_topic(depth_topic)


def depth_keys(config: Config) -> dict[str, str]:
    """The stack key each camera's depth image topic plays onto."""
    keys, first = Keys(config.stack.prefix), config.stack.camera
    return {
        depth_topics(config.ros2, first, camera).image: keys.depth(camera)
        for camera in config.all_cameras
    }


def frame_keys(config: Config) -> dict[str, str]:
    """The stack key each camera's image topics (raw and ``/compressed``) play onto."""
    keys, first = Keys(config.stack.prefix), config.stack.camera
    out: dict[str, str] = {}
    for camera in config.all_cameras:
        image = camera_topics(config.ros2, first, camera).image
        out[image] = out[f"{image.rstrip('/')}/compressed"] = keys.frame(camera)
    return out


@dataclass(slots=True)
class RecordedCamera:
    """What a recording holds of one camera's frames: its first frame's size and frame id, and
    how many frames there are between the first and last log time."""

    width: int
    height: int
    frame_id: str
    first_ns: int
    last_ns: int
    frames: int = 1
    depth: bool = False  # its depth images are played too
    announced: CameraAnnouncement | None = None  # as its source announced it when recorded

    def rate_hz(self) -> float | None:
        """The frames per second it was recorded at; None when that cannot be told (one frame,
        or every frame logged at one time)."""
        span_ns = self.last_ns - self.first_ns
        return (self.frames - 1) * 1e9 / span_ns if self.frames > 1 and span_ns > 0 else None


def _announcement(record: Record) -> CameraAnnouncement | None:
    """The camera announcement a record holds (the recorder's JSON), None for another record
    or a bad one (it is then as if not recorded)."""
    if record.stack_type != "CameraAnnouncement":
        return None
    try:
        body = record.json()
        known = (f.name for f in dataclasses.fields(CameraAnnouncement))
        return CameraAnnouncement(**{name: body[name] for name in known if name in body})
    except (DecodeError, TypeError, ValueError) as exc:
        log.warning("ignored a bad camera announcement on %s: %s", record.channel.topic,
                    one_line(exc))  # fmt: skip
        return None


def recorded_cameras(config: Config, path: Path, topics: list[str]) -> dict[str, RecordedCamera]:
    """Each camera whose frames ``topics`` of ``path`` play (onto its key, as
    :func:`one_pass` plays them), by name, from one reading of the file: with its depth when
    ``topics`` play its depth images too, and its last recorded announcement. Frames before
    the first that decodes are not counted (the play skips them too)."""
    keys = Keys(config.stack.prefix)
    cameras = {keys.frame(c): c for c in config.all_cameras}
    depths = {keys.depth(c): c for c in config.all_cameras}
    onto, first_camera = frame_keys(config), config.stack.camera
    depth_onto = depth_keys(config)
    out: dict[str, RecordedCamera] = {}
    with_depth: set[str] = set()
    announced: dict[str, CameraAnnouncement] = {}
    wanted = set(topics)
    with Recording(path) as rec:
        for record in rec.records():
            said = _announcement(record)
            if said is not None:
                announced[said.camera] = said
            kind = input_kind(record) if record.channel.topic in wanted else None
            if kind is Input.DEPTH:
                with_depth.add(depths.get(depth_onto.get(record.channel.topic, ""), first_camera))
            if kind is not Input.FRAME:
                continue
            camera = cameras.get(onto.get(record.channel.topic, ""), first_camera)
            log_ns = record.message.log_time
            seen = out.get(camera)
            if seen is not None:
                seen.frames += 1
                seen.first_ns, seen.last_ns = min(seen.first_ns, log_ns), max(seen.last_ns, log_ns)
                continue
            try:
                frame = decode_input(record, config.ros2.distro, source=SOURCE, seq=1)
            except DecodeError:
                continue
            if isinstance(frame, Frame):
                out[camera] = RecordedCamera(
                    frame.width, frame.height, frame.header.frame_id, log_ns, log_ns
                )
    for camera, seen in out.items():
        seen.depth, seen.announced = camera in with_depth, announced.get(camera)
    return out


def announce_played(
    config: Config,
    announcements: CameraAnnouncements,
    recorded: dict[str, RecordedCamera],
    rate: float,
) -> None:
    """Announce each camera of ``recorded`` as it is played at speed ``rate``: its mounting
    and field of view as recorded (its config's when no announcement was)."""
    for camera, seen in recorded.items():
        c, was = config.all_cameras[camera], seen.announced
        # With none recorded, its config's view and no mounting: where it stood is unknown.
        described = (
            was
            if was is not None
            else dataclasses.replace(c, mount_height_m=0.0, mount_x_m=0.0, mount_y_m=0.0)
        )
        announcements.announce(
            camera, described, rate_hz=(seen.rate_hz() or c.rate_hz) * rate,
            frame_id=c.frame_id, width=seen.width, height=seen.height, depth=seen.depth,
        )  # fmt: skip
        announcements.saw(camera, seen.width, seen.height, seen.frame_id)  # the recorded id


def one_pass(
    config: Config,
    path: Path,
    topics: list[str],
    rate: float,
    put: Callable[[str, bytes], object],
    stop: threading.Event,
    played: Played,
) -> None:
    """Publish ``topics`` of ``path`` once, through ``put`` (the stack key, the payload), at
    their recorded timing over ``rate``; counted in ``played``. RecordingError for a truncated
    file, after playing it."""
    schedule: Schedule | None = None
    distro = config.ros2.distro
    keys = Keys(config.stack.prefix)
    cameras, first_camera = frame_keys(config), keys.frame(config.stack.camera)
    depths, first_depth = depth_keys(config), keys.depth(config.stack.camera)
    info_of = info_topics(config)
    infos: dict[str, Any] = {}  # the last CameraInfo on each topic
    with Recording(path) as rec:
        for index, record in enumerate(rec.records(topics)):
            kind = input_kind(record)
            if kind is None:
                continue
            topic = record.channel.topic
            log_ns = record.message.log_time
            if schedule is None:
                schedule = Schedule(rate, now(), log_ns)
            due = schedule.due(log_ns)
            if stop.wait(max(0.0, (due.mono_ns - now().mono_ns) / 1e9)):
                return
            seq = record.message.sequence or index + 1
            try:
                if kind is Input.DEPTH_INFO:
                    infos[topic] = decode_info(record, distro)
                    continue
                beside = info_topic_of(info_of, topic)
                msg = _decode(record, kind, infos.get(beside), beside, distro, seq)
            except DecodeError as exc:
                played.bad_input += 1
                log.warning("skipped a bad message on %s: %s", topic, one_line(exc))
                continue
            if msg is None:
                continue
            at = schedule.restamp(log_ns, msg.header.stamp_ns)
            header = Header(
                stamp_ns=at.wall_ns, frame_id=msg.header.frame_id, seq=seq, source=SOURCE,
                mono_ns=at.mono_ns, boot_id=BOOT_ID,
            )  # fmt: skip
            out: Frame | DepthFrame | LaserScan = dataclasses.replace(msg, header=header)
            if isinstance(out, Frame):
                put(cameras.get(topic, first_camera), out.encode())
                played.frames += 1
            elif isinstance(out, DepthFrame):
                put(depths.get(topic, first_depth), out.encode())
                played.depths += 1
            else:
                put(keys.scan(), out.encode())
                played.scans += 1
        played.truncated = rec.truncated
    if played.truncated:
        raise RecordingError(
            f"{path}: truncated (no end after the last full chunk): played {played.frames} "
            f"frames, {played.depths} depth images and {played.scans} scans, the rest is lost"
        )


def _decode(
    record: Record, kind: Input, info: Any, beside: str, distro: RosDistro, seq: int
) -> Frame | DepthFrame | LaserScan | None:
    """The message a frame, depth image or scan record plays as; DecodeError for garbage, and
    for a depth image with no CameraInfo (``info``, the last on ``beside``) before it."""
    if kind is not Input.DEPTH:
        return decode_input(record, distro, source=SOURCE, seq=seq)
    if info is None:
        raise DecodeError(f"a depth image with no CameraInfo on {beside} before it")
    return decode_depth(record, info, distro, source=SOURCE, seq=seq)
