"""The recorder's contract: its counters and what it reads and (playing back) puts. Imports
only ``common``.

It listens to everything; playing a recording back puts frames, depth images and scans (and
announces the cameras it plays), on a stack that runs no live sensor only: a replay must never
reach a live robot's keys.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from common.access import Access, Shape, service_access
from common.counters import COMMON
from common.errors import ConfigError
from common.setting_checks import Range, check_bounds, enum_field

RECEIVED = "received"
WRITTEN = "written"
DROPPED = "dropped"  # the writer's queue was full

COUNTERS = frozenset({*COMMON, RECEIVED, WRITTEN, DROPPED})
PER_CAMERA: frozenset[str] = frozenset()

SERVICE = "recorder"


def access(shape: Shape) -> dict[str, Access]:
    keys = shape.keys
    depths = tuple(map(keys.depth, shape.cameras))
    replay = () if shape.live_sensors else (*shape.frames(), *depths, keys.scan())
    announced = (
        () if shape.live_sensors else tuple(map(keys.camera_announcements_of, shape.cameras))
    )
    return {
        SERVICE: service_access(
            keys,
            SERVICE,
            *replay,
            read=(f"{keys.prefix}/**",),
            token=(keys.health(SERVICE), *announced),
        )
    }


# -- settings -------------------------------------------------------------------------------------
class Compression(StrEnum):
    LZ4 = "lz4"  # fast: a few ms per MB, what a recorder beside a CPU detector can afford
    ZSTD = "zstd"  # smaller files, several times the CPU
    NONE = "none"


#: What ``file_pattern`` may contain: ``{time}`` becomes the start time, YYYYmmdd-HHMMSS.
TIME_FIELD = "{time}"


@dataclass(frozen=True, slots=True, kw_only=True)
class RecorderSettings:
    """Where recordings go and how they are written.

    The recorder service (and ``zstack record`` without ``--out``) writes
    ``output_dir/file_pattern`` (``output_dir`` relative to the repo root), ``{time}`` replaced
    by the start time. Subscribers only push into a queue of ``queue_size`` messages; one
    thread writes; a full queue drops the message and counts it (the bus is never blocked).
    Messages are written in compressed chunks of ``chunk_size_kb``; a chunk is also closed
    every ``flush_period_s``, so a recorder that is killed loses at most that much.
    A progress line (messages, MB, drops) every ``progress_period_s``. ``zstack record``
    warns when it has heard nothing of the stack after ``silence_warning_s``, and fails at the
    end if it never did. ``zstack play`` (and ``zstack compare``'s replay) waits up to
    ``detector_wait_s`` for a detector to be ready before its first frame, else fails saying
    so (``--no-wait`` plays at once).

    On a small robot computer the recorder shares the cores with the detector, and a recording
    must take only the time perception leaves over (common/priority.py). With ``sched_idle``
    (Linux ``SCHED_IDLE``, the default) it runs only on a core nothing else wants: on a machine
    that perception keeps busy all the time it then falls behind, and the queue drops and counts
    what it could not write (the progress line says so). ``sched_idle = false`` shares the CPU
    by ``nice`` (0..19) instead: a smaller share, but one taken even mid-inference. Either ranks
    the recorder only against the processes of its own session: the supervisor's services
    share its session; a ``zstack record`` typed at another terminal does not.
    """

    output_dir: str = "recordings"
    file_pattern: str = "stack-{time}.mcap"
    queue_size: Annotated[int, Range(1, 100_000)] = 256
    chunk_size_kb: Annotated[int, Range(16, 65536)] = 1024
    compression: Compression = Compression.LZ4
    flush_period_s: Annotated[float, Range(0.05, 60)] = 1.0
    progress_period_s: Annotated[float, Range(0.1, 3600)] = 5.0
    silence_warning_s: Annotated[float, Range(0.5, 3600)] = 5.0
    detector_wait_s: Annotated[float, Range(1, 3600)] = 120.0
    nice: Annotated[int, Range(0, 19)] = 10
    sched_idle: bool = True

    def __post_init__(self) -> None:
        enum_field(self, "compression", Compression, "recorder.compression")
        if not self.output_dir:
            raise ConfigError("recorder.output_dir must not be empty")
        if not self.file_pattern.endswith(".mcap") or "/" in self.file_pattern:
            raise ConfigError(
                f"recorder.file_pattern must be a file name ending in .mcap, "
                f"got {self.file_pattern!r}"
            )
        check_bounds(self, "recorder", RecorderSettings)


#: The stack config's tables this service reads (stack/config.py's Config has each).
SETTINGS_TABLES = {"recorder": RecorderSettings}
