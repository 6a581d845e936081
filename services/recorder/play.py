"""Playing a recording back: its frames and scans, for the stack's own keys, at their original
timing (times 1/rate), restamped to now (timing.py), as the camera or the simulator would
publish them. The detector and the controller then run on recorded data. No zenoh here:
``service.play`` opens the session and publishes what :func:`one_pass` hands it.

The file is read once to check it (reading.py) before anything is published. Each frame keeps
its recorded sequence number (the MCAP message's ``sequence``, our recorder writes the stack
header's ``seq``; a ROS 2 bag's count otherwise), so that detections made on the replay can be
matched with the recorded ones (compare.py); its source is ``replay``. Under the secure profile
the player joins as the ``recorder`` principal, which may publish frames and scans.

With several cameras each camera's frames go back on its own key: an image topic is the camera
whose ROS 2 topic it is (``ros2.camera_namespace``, as the recorder wrote it and the bridge
maps it, :func:`frame_keys`); an image topic of no configured camera (a bag from another
robot) plays as the first camera's, as with one camera.

Each camera whose frames are played is announced while the play lasts (CameraAnnouncement,
common/camera_announce.py): the size and frame id of its first recorded frame, the rate it
was recorded at times the play's speed (its configured rate when the recording cannot tell:
one frame), its mounting and field of view from its config (:func:`recorded_cameras`,
:func:`announce_played`).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from common.camera_announce import CameraAnnouncements
from common.clock import BOOT_ID, now
from common.errors import DecodeError, RecordingError, one_line
from common.keys import Keys
from common.messages import Frame, Header, LaserScan
from services.recorder.reading import (
    PLAYABLE,
    Input,
    Recording,
    check_playable,
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
    scans: int = 0
    bad_input: int = 0
    passes: int = 0
    truncated: bool = False


def playable_topics(path: Path, topics: Sequence[str] | None) -> list[str]:
    """The topics to play from ``path`` (all frames and scans when ``topics`` is None), after
    reading the whole file once; RecordingError for a file that cannot be played."""
    with Recording(path) as rec:
        channels = rec.scan()
    check_playable(channels, topics)
    if topics is not None:
        return list(topics)
    return [topic for topic, enc, schema in channels if enc == "cdr" and schema in PLAYABLE]


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

    def rate_hz(self) -> float | None:
        """The frames per second it was recorded at; None when that cannot be told (one frame,
        or every frame logged at one time)."""
        span_ns = self.last_ns - self.first_ns
        return (self.frames - 1) * 1e9 / span_ns if self.frames > 1 and span_ns > 0 else None


def recorded_cameras(config: Config, path: Path, topics: list[str]) -> dict[str, RecordedCamera]:
    """Each camera whose frames ``topics`` of ``path`` play (onto its key, as
    :func:`one_pass` plays them), by name, from one reading of the file. Frames before the
    first that decodes are not counted (the play skips them too)."""
    keys = Keys(config.stack.prefix)
    cameras = {keys.frame(c): c for c in config.all_cameras}
    onto, first_camera = frame_keys(config), config.stack.camera
    out: dict[str, RecordedCamera] = {}
    with Recording(path) as rec:
        for record in rec.records(topics):
            if input_kind(record) is not Input.FRAME:
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
    return out


def announce_played(
    config: Config,
    announcements: CameraAnnouncements,
    recorded: dict[str, RecordedCamera],
    rate: float,
) -> None:
    """Announce each camera of ``recorded`` as it is played at speed ``rate``."""
    for camera, seen in recorded.items():
        c = config.all_cameras[camera]
        announcements.announce(
            camera,
            rate_hz=(seen.rate_hz() or c.rate_hz) * rate,
            mount_yaw_deg=c.mount_yaw_deg,
            hfov_deg=c.hfov_deg,
            frame_id=c.frame_id,
            width=seen.width,
            height=seen.height,
        )
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
    with Recording(path) as rec:
        for index, record in enumerate(rec.records(topics)):
            log_ns = record.message.log_time
            if schedule is None:
                schedule = Schedule(rate, now(), log_ns)
            due = schedule.due(log_ns)
            if stop.wait(max(0.0, (due.mono_ns - now().mono_ns) / 1e9)):
                return
            seq = record.message.sequence or index + 1
            try:
                msg = decode_input(record, distro, source=SOURCE, seq=seq)
            except DecodeError as exc:
                played.bad_input += 1
                log.warning("skipped a bad message on %s: %s", record.channel.topic, one_line(exc))
                continue
            if msg is None:
                continue
            at = schedule.restamp(log_ns, msg.header.stamp_ns)
            header = Header(
                stamp_ns=at.wall_ns, frame_id=msg.header.frame_id, seq=seq, source=SOURCE,
                mono_ns=at.mono_ns, boot_id=BOOT_ID,
            )  # fmt: skip
            out: Frame | LaserScan = dataclasses.replace(msg, header=header)
            if isinstance(out, Frame):
                put(cameras.get(record.channel.topic, first_camera), out.encode())
                played.frames += 1
            else:
                put(keys.scan(), out.encode())
                played.scans += 1
        played.truncated = rec.truncated
    if played.truncated:
        raise RecordingError(
            f"{path}: truncated (no end after the last full chunk): played {played.frames} "
            f"frames and {played.scans} scans, the rest is lost"
        )
