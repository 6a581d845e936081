"""Playing a recording back: its frames and scans, for the stack's own keys, at their original
timing (times 1/rate), restamped to now (timing.py), as the camera or the simulator would
publish them. The detector and the controller then run on recorded data. No zenoh here:
``service.play`` opens the session and publishes what :func:`one_pass` hands it.

The file is read once to check it (reading.py) before anything is published. Each frame keeps
its recorded sequence number (the MCAP message's ``sequence``, our recorder writes the stack
header's ``seq``; a ROS 2 bag's count otherwise), so that detections made on the replay can be
matched with the recorded ones (compare.py); its source is ``replay``. Under the secure profile
the player joins as the ``recorder`` principal, which may publish frames and scans.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from common.clock import BOOT_ID, now
from common.errors import DecodeError, RecordingError, one_line
from common.messages import Frame, Header, LaserScan
from common.settings import Config
from services.recorder.reading import PLAYABLE, Input, Recording, check_playable, decode_input
from services.recorder.timing import Schedule

log = logging.getLogger("recorder")

SOURCE = "replay"


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


def one_pass(
    config: Config,
    path: Path,
    topics: list[str],
    rate: float,
    put: Callable[[Input, bytes], object],
    stop: threading.Event,
    played: Played,
) -> None:
    """Publish ``topics`` of ``path`` once, through ``put``, at their recorded timing over
    ``rate``; counted in ``played``. RecordingError for a truncated file, after playing it."""
    schedule: Schedule | None = None
    distro = config.ros2.distro
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
            kind = Input.FRAME if isinstance(out, Frame) else Input.SCAN
            put(kind, out.encode())
            if kind is Input.FRAME:
                played.frames += 1
            else:
                played.scans += 1
        played.truncated = rec.truncated
    if played.truncated:
        raise RecordingError(
            f"{path}: truncated (no end after the last full chunk): played {played.frames} "
            f"frames and {played.scans} scans, the rest is lost"
        )
