"""The recorder on the bus: every stack key into an MCAP file (writer.py), never blocking.

Runs as a service under the supervisor (listed in ``[supervisor].services``: a whole run is
recorded) or from the command line (``zstack record``: until Ctrl-C or ``--duration``). The
subscriber callbacks only copy the payload into the bounded queue; a full queue drops and
counts. The counters (``received``, ``written``, ``dropped``, ``bad_input``) go to the metrics
service as ``recorder.*``; a progress line says messages, MB and drops.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from datetime import datetime
from math import inf
from pathlib import Path

import zenoh

from common import reach
from common.clock import local_now, mono_s, wall_ns
from common.codec import Message
from common.errors import StackError
from common.keys import Keys
from common.lifecycle import EXIT_FAILED, EXIT_OK, Progress
from common.messages import (
    ControllerStatus,
    Detections,
    EStop,
    Frame,
    GroundTruth,
    LaserScan,
    ServiceCounters,
    Twist,
)
from common.node import Node
from common.priority import lower_priority
from common.recorder_settings import TIME_FIELD
from common.settings import REPO_ROOT, Config
from services.recorder.channels import Translator
from services.recorder.writer import Decode, McapFile, QueuedRecorder

SERVICE = "recorder"


def subscriptions(keys: Keys, camera: str) -> dict[str, type[Message]]:
    """Every key the recorder listens to, and its message type."""
    return {
        keys.frame(camera): Frame,
        keys.all_detections(): Detections,
        keys.scan(): LaserScan,
        keys.cmd_vel(): Twist,
        keys.controller_status(): ControllerStatus,
        keys.estop(): EStop,
        keys.sim_truth(): GroundTruth,
        keys.all_counters(): ServiceCounters,
    }


def default_path(config: Config, at: datetime | None = None) -> Path:
    """``recorder.output_dir / recorder.file_pattern`` with ``{time}`` filled in."""
    s = config.recorder
    stamp = (at or local_now()).strftime("%Y%m%d-%H%M%S")
    folder = Path(s.output_dir).expanduser()
    folder = folder if folder.is_absolute() else REPO_ROOT / folder
    return folder / s.file_pattern.replace(TIME_FIELD, stamp)


class Recorder:
    """A recording in progress on ``node``'s session; :meth:`close` finishes the file."""

    def __init__(self, node: Node, path: Path) -> None:
        config = node.config
        self.node = node
        self.path = path
        self._queued = QueuedRecorder(
            McapFile(path, config.recorder), Translator(config.ros2), config.recorder,
            node.counters,
        )  # fmt: skip
        self._subs: list[zenoh.Subscriber[None]] = []
        self._own = node.keys.counters(SERVICE)
        self.heard = 0  # samples from the stack: every key but the recorder's own counters
        for key, cls in subscriptions(node.keys, config.stack.camera).items():
            self._subs.append(node.session.declare_subscriber(key, self._offer(cls.decode)))

    def _offer(self, decode: Decode) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            # Zenoh's thread: copy the bytes and queue them, nothing else.
            key = str(sample.key_expr)
            if key != self._own:
                self.heard += 1  # one writer per subscriber thread; a count, never a decision
            self._queued.offer(key, sample.payload.to_bytes(), wall_ns(), decode)

        return on_sample

    @property
    def failed(self) -> Exception | None:
        return self._queued.failed

    def progress(self) -> str:
        c = self.node.counters
        mb = self._queued.file.bytes_written / 1e6
        line = (
            f"recording {self.path}: {c.get('written')} messages, {mb:.1f} MB written, "
            f"{c.get('dropped')} dropped"
        )
        if c.get("dropped"):
            line += " (the writer could not keep up)"
        if c.get("bad_input"):
            line += f", {c.get('bad_input')} bad input"
        return line

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._queued.close()


def record(
    config: Config,
    path: Path,
    stop: threading.Event,
    progress: Progress,
    duration_s: float = 0.0,
    *,
    require_stack: bool = False,
) -> int:
    """Record until ``stop`` is set or ``duration_s`` (0: no limit) has passed.

    ``require_stack`` (the command line): warn once when nothing of the stack has been heard
    after ``recorder.silence_warning_s``, and fail (exit 1, the file kept) when nothing was
    heard at all: a recording of the recorder's own counters is not a recording of a stack.
    """
    priority = lower_priority(config.recorder.nice, config.recorder.sched_idle)
    with Node(SERVICE, config) as node:
        node.log.info("CPU priority: %s", priority)
        recorder = Recorder(node, path)
        node.ready()
        progress(f"recording to {path}")
        period = config.recorder.progress_period_s
        end = mono_s() + duration_s if duration_s > 0 else float("inf")
        next_line = mono_s() + period
        warn_at = mono_s() + config.recorder.silence_warning_s if require_stack else inf
        where = reach.describe(config.zenoh, config.stack.prefix, SERVICE)
        code = EXIT_OK
        try:
            while not stop.is_set() and mono_s() < end:
                stop.wait(min(0.2, max(0.0, end - mono_s())))
                node.publish_counters()
                if recorder.failed is not None:
                    code = EXIT_FAILED
                    break
                if mono_s() >= next_line:
                    next_line += period
                    progress(recorder.progress())
                if recorder.heard == 0 and mono_s() >= warn_at:
                    warn_at = inf
                    progress(f"warning: nothing heard from the stack yet at {where}")
        finally:
            recorder.close()
        progress(recorder.progress() + (" (stopped by an error)" if code else ", done"))
        if code == EXIT_OK and require_stack and recorder.heard == 0:
            linked = reach.connected(node.session)
            raise StackError(
                reach.unreached(
                    f"recorded nothing from the stack ({path} holds only the recorder's own "
                    "counters)",
                    config.zenoh,
                    config.stack.prefix,
                    SERVICE,
                    linked=linked,
                )
            )
        return code
