"""Reading a recording: ours, or a ROS 2 bag written with the storage ``mcap``. No zenoh.

Messages are read in file order, chunk by chunk, with their CRCs checked, so a file whose end
is missing (a recorder that was killed) gives every message up to its last full chunk; the
caller learns that it ended early from :attr:`Recording.truncated`. Anything that is not a
readable MCAP raises :class:`common.errors.RecordingError` with one line.

The inputs a replay publishes are decoded here: ``sensor_msgs/msg/Image`` and
``CompressedImage`` as Frames, ``sensor_msgs/msg/LaserScan`` as LaserScan (services.ros2's
translations), and an ``Image`` on a depth topic with the ``CameraInfo`` beside it as a
DepthFrame (depth_ros.py).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader
from mcap.records import Channel, Message, Schema

from common.errors import DecodeError, RecordingError, one_line
from common.lifecycle import Closing
from common.messages import DepthFrame, Frame, LaserScan
from rosmsg.convert import LASER_SCAN, cdr_decode, scan_from_ros
from rosmsg.depth import CAMERA_INFO
from rosmsg.distro import RosDistro
from rosmsg.images import COMPRESSED_IMAGE, IMAGE, frame_from_compressed_image, frame_from_image
from services.recorder.channels import CDR, JSON, MEMORY_SCAN, STACK_MESSAGE, VIRTUAL_SCAN
from services.recorder.depth_ros import (
    RANGE_MAX,
    RANGE_MIN,
    depth_from_ros,
    is_depth_topic,
)

MAGIC = b"\x89MCAP0\r\n"
#: The largest record read; a corrupt length field must not become a huge allocation.
RECORD_SIZE_LIMIT = 1 << 30


class Input(StrEnum):
    FRAME = "frame"
    SCAN = "scan"
    DEPTH = "depth"  # an Image on a depth topic (depth_ros.is_depth_topic)
    DEPTH_INFO = "depth_info"  # a CameraInfo: the intrinsics of the depth image beside it


#: The ROS types a replay can publish, and what each becomes.
PLAYABLE = {IMAGE: Input.FRAME, COMPRESSED_IMAGE: Input.FRAME, LASER_SCAN: Input.SCAN}


@dataclass(frozen=True, slots=True)
class Record:
    """One message of a recording with its channel and schema (None for a schemaless one)."""

    schema: Schema | None
    channel: Channel
    message: Message

    @property
    def stack_type(self) -> str:
        return self.channel.metadata.get(STACK_MESSAGE, "")

    def json(self) -> dict[str, Any]:
        """The payload of a JSON channel; DecodeError for anything else."""
        if self.channel.message_encoding != JSON:
            raise DecodeError(f"{self.channel.topic}: not a JSON channel")
        try:
            value = json.loads(self.message.data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise DecodeError(f"{self.channel.topic}: not JSON ({one_line(exc)})") from exc
        if not isinstance(value, dict):
            raise DecodeError(f"{self.channel.topic}: a JSON message must be an object")
        return value


def _mcap_file(path: Path) -> Path:
    """``path``, or for a ROS 2 bag's folder the one ``.mcap`` file in it."""
    if not path.is_dir():
        return path
    files = sorted(path.glob("*.mcap"))
    if len(files) != 1:
        raise RecordingError(
            f"{path}: a bag folder must hold exactly one .mcap file, found {len(files)}"
        )
    return files[0]


class Recording(Closing):
    """An MCAP file opened for reading; iterate :meth:`records` once per pass."""

    def __init__(self, path: str | Path) -> None:
        self.path = _mcap_file(Path(path))
        try:
            self._file: IO[bytes] = self.path.open("rb")
            head = self._file.read(len(MAGIC))
        except OSError as exc:
            raise RecordingError(f"{self.path}: cannot read ({one_line(exc)})") from exc
        if head != MAGIC:
            self._file.close()
            raise RecordingError(f"{self.path}: not an MCAP file (no MCAP magic at its start)")
        self.truncated = False
        self.count = 0

    def records(self, topics: Iterable[str] | None = None) -> Iterator[Record]:
        """Every message in file order (``topics``: only those). At a missing end it stops and
        sets :attr:`truncated`; at corrupt data it raises RecordingError."""
        self._file.seek(0)
        self.truncated, self.count = False, 0
        reader = NonSeekingReader(
            self._file, validate_crcs=True, record_size_limit=RECORD_SIZE_LIMIT
        )
        wanted = None if topics is None else list(topics)
        stream = reader.iter_messages(topics=wanted, log_time_order=False)
        while True:
            try:
                schema, channel, message = next(stream)
            except StopIteration:
                return
            except EndOfFile:
                self.truncated = True
                return
            except Exception as exc:  # the mcap reader and its decompressors raise many kinds
                raise RecordingError(
                    f"{self.path}: corrupt MCAP after {self.count} messages ({one_line(exc)})"
                ) from exc
            self.count += 1
            yield Record(schema, channel, message)

    def scan(self) -> list[tuple[str, str, str]]:
        """Read the whole file once (checking it) and return its channels as (topic, message
        encoding, schema name), in order of first use."""
        seen: dict[str, tuple[str, str, str]] = {}
        for record in self.records():
            topic = record.channel.topic
            if topic not in seen:
                schema = record.schema.name if record.schema is not None else ""
                seen[topic] = (topic, record.channel.message_encoding, schema)
        if self.truncated and not seen:
            raise RecordingError(f"{self.path}: truncated before its first full chunk: no messages")
        return list(seen.values())

    def close(self) -> None:
        self._file.close()


def input_kind(record: Record) -> Input | None:
    """What ``record`` plays as, or None when it is no frame, depth image, scan or
    CameraInfo."""
    if record.schema is None or record.channel.message_encoding != CDR:
        return None
    if VIRTUAL_SCAN in record.channel.metadata or MEMORY_SCAN in record.channel.metadata:
        return None  # what the depth scan stage made of the depth, never the laser: not played
    name = record.schema.name
    if name == CAMERA_INFO:
        return Input.DEPTH_INFO
    if name == IMAGE and (
        record.stack_type == "DepthFrame" or is_depth_topic(record.channel.topic)
    ):
        return Input.DEPTH
    return PLAYABLE.get(name)


def check_playable(channels: Iterable[tuple[str, str, str]], topics: Iterable[str] | None) -> None:
    """RecordingError unless every asked-for topic (``topics``; all when None) can be played and
    something can. ``channels`` are (topic, message encoding, schema name)."""
    seen = {topic: (encoding, schema) for topic, encoding, schema in channels}
    if topics is not None:
        for topic in topics:
            if topic not in seen:
                known = ", ".join(sorted(seen)) or "none"
                raise RecordingError(f"no topic {topic!r} in the recording (topics: {known})")
            encoding, schema = seen[topic]
            if encoding != CDR or schema not in PLAYABLE:
                raise RecordingError(
                    f"topic {topic!r} has the unknown schema {schema or encoding!r}: "
                    f"a replay plays {', '.join(PLAYABLE)} (CDR)"
                )
        return
    if not any(enc == CDR and schema in PLAYABLE for enc, schema in seen.values()):
        found = ", ".join(sorted({s or e for e, s in seen.values()})) or "no messages"
        raise RecordingError(
            f"nothing to play: no {', '.join(PLAYABLE)} in the recording (found: {found})"
        )


def decode_input(
    record: Record, distro: RosDistro, *, source: str, seq: int
) -> Frame | LaserScan | None:
    """The Frame or LaserScan in ``record`` (None when it is neither); DecodeError for garbage.

    Its header is the recorded one (the caller restamps it): ``seq`` and ``source`` as given.
    """
    if input_kind(record) not in (Input.FRAME, Input.SCAN):
        return None
    assert record.schema is not None
    ros = cdr_decode(distro, record.schema.name, record.message.data)
    if record.schema.name == IMAGE:
        return frame_from_image(ros, source=source, seq=seq)
    if record.schema.name == COMPRESSED_IMAGE:
        return frame_from_compressed_image(ros, source=source, seq=seq)
    return scan_from_ros(ros, source=source, seq=seq)


def decode_info(record: Record, distro: RosDistro) -> Any:
    """The CameraInfo in ``record`` (a DEPTH_INFO one); DecodeError for garbage."""
    return cdr_decode(distro, CAMERA_INFO, record.message.data)


def recorded_range(record: Record) -> tuple[float, float]:
    """The sensor's valid range (min, max) a depth image channel's metadata states; (0, 0),
    not stated, when it states none or garbage."""
    meta = record.channel.metadata
    try:
        low, high = float(meta.get(RANGE_MIN, 0.0)), float(meta.get(RANGE_MAX, 0.0))
    except ValueError:
        return 0.0, 0.0
    sane = math.isfinite(low + high) and low >= 0 and (high == 0 or low < high)
    return (low, high) if sane else (0.0, 0.0)


def decode_depth(
    record: Record, info: Any, distro: RosDistro, *, source: str, seq: int
) -> DepthFrame:
    """The DepthFrame of a depth image ``record`` (a DEPTH one) with the intrinsics of
    ``info`` (its CameraInfo, :func:`decode_info`); DecodeError for garbage. Its header is the
    recorded one (the caller restamps it)."""
    image = cdr_decode(distro, IMAGE, record.message.data)
    return depth_from_ros(image, info, source=source, seq=seq, range_m=recorded_range(record))
