"""The recorder on the bus: every stack key into an MCAP file (writer.py), never blocking.

Runs as a service under the supervisor (listed in ``[supervisor].services``: a whole run is
recorded) or from the command line (``zstack record``: until Ctrl-C or ``--duration``). The
subscriber callbacks only copy the payload into the bounded queue; a full queue drops and
counts. The counters (``received``, ``written``, ``dropped``, ``bad_input``) go to the metrics
service as ``recorder.*``; a progress line says messages, MB and drops.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from datetime import datetime
from functools import partial
from math import inf
from pathlib import Path

from common import reach
from common.announce import from_chunk
from common.bus import Bus, Declared, QoS
from common.camera_announce import CameraAnnouncements
from common.clock import SYSTEM_CLOCK, Clock, local_now, mono_s
from common.codec import Message
from common.errors import StackError
from common.keys import Keys
from common.lifecycle import EXIT_FAILED, EXIT_OK, Closing, Progress
from common.messages import (
    CameraAnnouncement,
    ControllerStatus,
    DepthFrame,
    Detections,
    EStop,
    Frame,
    GroundTruth,
    LaserScan,
    ServiceCounters,
    Twist,
)
from common.node import Node, Tally
from common.pool_rule import pool_name
from common.priority import leave_idle, lower_priority, process_threads
from common.queries import ready_services
from common.settings import REPO_ROOT, is_detector_service
from common.zenoh_bus import ZenohBus, open_session
from services.recorder import contract
from services.recorder.channels import Translator
from services.recorder.contract import TIME_FIELD
from services.recorder.play import (
    ANNOUNCED_SOURCE,
    Played,
    announce_played,
    one_pass,
    playable_topics,
    recorded_cameras,
)
from services.recorder.writer import Decode, McapFile, QueuedRecorder
from stack.access_table import running_sensors
from stack.config import Config

SERVICE = "recorder"
#: The share of the supervisor's stop timeout that a stop spends writing what is queued. The
#: rest is for what comes around it, all slow at nice 10 on cores kept busy (the recorder then
#: gets a tenth of a core): seeing the stop (up to 1 s after the SIGTERM, measured with two
#: CPU burners beside the default stack), the item being written and the file's end (0.5 s
#: past the budget), the session's close, the exit (__main__.py). With half (2.5 s of 5) the
#: stack's stop took 4.1 s of its 5 there; with this share 3.5 to 3.9 s (and 1.6 to 4.2 s with
#: 640x480 colour and depth at 15 Hz, the recorder beside metrics only).
CLOSE_SHARE = 0.35


def subscriptions(keys: Keys, cameras: Sequence[str]) -> dict[str, type[Message]]:
    """Every key the recorder listens to, and its message type: each of ``cameras``' frames
    and depth images, every camera's detections."""
    return {
        **{keys.frame(camera): Frame for camera in cameras},
        **{keys.depth(camera): DepthFrame for camera in cameras},
        keys.all_detections(): Detections,
        keys.scan(): LaserScan,
        keys.all_virtual_scans(): LaserScan,  # each depth camera's, as the depth stage made it
        keys.remembered_scan(): LaserScan,  # the depth memory's, round the robot
        keys.known_floor(): LaserScan,  # how far ahead the floor is known
        keys.cmd_vel(): Twist,
        keys.controller_status(): ControllerStatus,
        keys.estop(): EStop,
        keys.sim_truth(): GroundTruth,
        keys.all_counters(): ServiceCounters,
    }


def _announcement(chunk: bytes) -> CameraAnnouncement:
    """The CameraAnnouncement of a token's key chunk (DecodeError for garbage): decoded on the
    writer thread, as every payload is."""
    return from_chunk(CameraAnnouncement.decode, chunk.decode("ascii", "replace"))


def default_path(config: Config, at: datetime | None = None) -> Path:
    """``recorder.output_dir / recorder.file_pattern`` with ``{time}`` filled in."""
    s = config.recorder
    stamp = (at or local_now()).strftime("%Y%m%d-%H%M%S")
    folder = Path(s.output_dir).expanduser()
    folder = folder if folder.is_absolute() else REPO_ROOT / folder
    return folder / s.file_pattern.replace(TIME_FIELD, stamp)


class Recorder(Closing):
    """A recording in progress: :meth:`on_sample` queues what a subscriber hears for the writer
    thread (writer.py), :meth:`listen` subscribes it to every key on a node's session, and
    :meth:`close` finishes the file."""

    def __init__(
        self, tally: Tally, path: Path, config: Config, *, clock: Clock = SYSTEM_CLOCK
    ) -> None:
        self.tally = tally
        self.path = path
        self._clock = clock  # each message's log time: its wall time as it is heard
        self._queued = QueuedRecorder(
            McapFile(path, config.recorder), Translator(config.ros2, config.stack.camera),
            config.recorder, tally.counters,
        )  # fmt: skip
        self._cameras = list(config.all_cameras)
        self._subs: list[Declared] = []
        self._keys = tally.keys
        #: At a stop, what is queued is written for at most this long (a share of the
        #: supervisor's stop timeout), so that the file is finished before it would kill the
        #: recorder: see CLOSE_SHARE.
        self._close_budget_s = config.supervisor.stop_timeout_s * CLOSE_SHARE
        self._own = tally.keys.counters(SERVICE)
        self.heard = 0  # samples from the stack: every key but the recorder's own counters

    def listen(self, node: Node) -> Recorder:
        """Subscribe to every key of :func:`subscriptions` on ``node``'s session, and watch
        the camera announcements."""
        for key, cls in subscriptions(node.keys, self._cameras).items():
            self._subs.append(node.subscribe_keyed(key, partial(self.on_sample, decode=cls.decode)))
        announced = node.keys.all_camera_announcements()
        self._subs.append(node.bus.watch_tokens(announced, self.on_token))
        return self

    def on_token(self, key: str, alive: bool) -> None:
        """Zenoh's thread: queue a camera announcement that appeared (on the camera's
        ``announce`` key, its token's chunk decoded later); one that goes is not recorded."""
        parts = self._keys.camera_announcement_parts(key)
        if not alive or parts is None:
            return
        camera, chunk = parts
        self.heard += 1
        where = self._keys.camera_announcements_of(camera).removesuffix("/*")
        chunk_bytes = chunk.encode("ascii", "replace")
        self._queued.offer(where, chunk_bytes, self._clock.wall_ns(), _announcement)

    def on_sample(self, key: str, payload: bytes, decode: Decode) -> None:
        """Zenoh's thread: queue the bytes heard on ``key`` (decoded later, on the writer
        thread, by ``decode``), nothing else."""
        if key != self._own:
            self.heard += 1  # one writer per subscriber thread; a count, never a decision
        self._queued.offer(key, payload, self._clock.wall_ns(), decode)

    @property
    def failed(self) -> Exception | None:
        return self._queued.failed

    def progress(self) -> str:
        c = self.tally.counters
        mb = self._queued.file.bytes_written / 1e6
        line = (
            f"recording {self.path}: {c.get('written')} messages, {mb:.1f} MB written, "
            f"{c.get('dropped')} dropped"
        )
        if c.get(contract.DROPPED):
            line += " (the writer could not keep up)"
        if c.get("bad_input"):
            line += f", {c.get('bad_input')} bad input"
        return line

    def close(self) -> None:
        # Out of the idle class first, every thread (Zenoh's too): undeclaring, finishing the
        # file and closing the session must end before the supervisor's stop timeout, and an
        # idle-class thread gets no CPU at all while every core is busy (a recorder killed
        # at stop with both cores busy, its subscriptions still being undeclared).
        self.tally.log.debug("stopping: %s", leave_idle(*process_threads()))
        for sub in self._subs:
            sub.undeclare()
        self._queued.close(self._close_budget_s)


def record(
    config: Config,
    path: Path,
    stop: threading.Event,
    progress: Progress,
    duration_s: float = 0.0,
    *,
    require_stack: bool = False,
    bus: Bus | None = None,
    clock: Clock = SYSTEM_CLOCK,
) -> int:
    """Record until ``stop`` is set or ``duration_s`` (0: no limit) has passed, on ``bus`` (a
    Zenoh session of the recorder's own unless given: an in-process test's) by ``clock``.

    ``require_stack`` (the command line): warn once when nothing of the stack has been heard
    after ``recorder.silence_warning_s``, and fail (exit 1, the file kept) when nothing was
    heard at all: a recording of the recorder's own counters is not a recording of a stack.
    """
    priority = lower_priority(config.recorder.nice, config.recorder.sched_idle)
    with Node(SERVICE, config, bus=bus, clock=clock) as node:
        node.log.info("CPU priority: %s", priority)
        with Recorder(node, path, config, clock=node.clock) as recorder:
            recorder.listen(node)
            node.ready()
            progress(f"recording to {path}")
            code = _record_until(config, node, recorder, stop, progress, duration_s, require_stack)
        progress(recorder.progress() + (" (stopped by an error)" if code else ", done"))
        if code == EXIT_OK and require_stack and recorder.heard == 0:
            raise StackError(
                reach.unreached(
                    f"recorded nothing from the stack ({path} holds only the recorder's own "
                    "counters)",
                    config.zenoh,
                    config.stack.prefix,
                    SERVICE,
                    linked=node.bus.linked(),
                )
            )
        return code


def _record_until(
    config: Config,
    node: Node,
    recorder: Recorder,
    stop: threading.Event,
    progress: Progress,
    duration_s: float,
    require_stack: bool,
) -> int:
    """The recording's loop: counters, progress lines and the silence warning, until ``stop``,
    the duration's end (0: none) or the writer's failure (EXIT_FAILED)."""
    s, now = config.recorder, node.clock.mono_s
    end = now() + duration_s if duration_s > 0 else inf
    next_line = now() + s.progress_period_s
    warn_at = now() + s.silence_warning_s if require_stack else inf
    where = reach.describe(config.zenoh, config.stack.prefix, SERVICE)
    while not stop.is_set() and now() < end:
        stop.wait(min(0.2, max(0.0, end - now())))
        node.publish_counters()
        if recorder.failed is not None:
            return EXIT_FAILED
        if now() >= next_line:
            next_line += s.progress_period_s
            progress(recorder.progress())
        if recorder.heard == 0 and now() >= warn_at:
            warn_at = inf
            progress(f"warning: nothing heard from the stack yet at {where}")
    return EXIT_OK


# The player joins as the recorder's principal, which may publish frames and scans.
PLAY_PRINCIPAL = SERVICE
# How long the player waits for a first link to the stack before saying it reached nothing
# (as the e-stop command does), and how often it asks which services are ready while it
# waits for a detector (recorder.detector_wait_s).
PLAY_LINK_TIMEOUT_S = 3.0
READY_POLL_S = 0.5


def _ready_to_play(
    config: Config,
    bus: Bus,
    path: Path,
    stop: threading.Event,
    progress: Progress,
    wait: bool,
    clear: Callable[[], None],
    served: Callable[[], bool] = lambda: True,
) -> set[str]:
    """The services ready on the stack once the replay may start: a link to the stack at once
    (else one StackError line naming the endpoint), no live sensor, and with ``wait`` a ready
    detector serving every played camera (``served()``) within recorder.detector_wait_s
    (frames played before would be lost). ``clear()`` is called once no live sensor is seen,
    before the wait for a detector (the played cameras are announced then: a pool's workers
    serve the cameras announced, each once it has heard its announcement)."""
    keys, prefix = Keys(config.stack.prefix), config.stack.prefix
    if not bus.linked(PLAY_LINK_TIMEOUT_S):
        raise StackError(
            reach.unreached(
                f"cannot play {path}: no link to the stack",
                config.zenoh, prefix, PLAY_PRINCIPAL, linked=False,
            )
        )  # fmt: skip
    deadline = mono_s() + (config.recorder.detector_wait_s if wait else 0.0)
    said = cleared = False
    while True:
        ready = ready_services(bus, keys, READY_POLL_S)
        live = running_sensors(ready)
        if live:
            # A replay onto a live robot's keys would mix old frames and scans with its own:
            # all-clear scans could blind its laser. Under the secure profile the router
            # refuses these puts anyway (stack/access.py); this says so before trying.
            raise StackError(
                f"refusing to play {path} onto stack {prefix!r}: it runs a live "
                f"sensor ({', '.join(live)}) and a replay would mix with or blind it; play into "
                "a stack without camera, sim or ros2 (e.g. supervisor.services = "
                '["detector", "controller", "metrics"])'
            )
        if not cleared:
            cleared = True
            clear()
        detector = any(is_detector_service(name) for name in ready)
        if detector and served():
            return ready
        if not wait:
            progress("no detector is ready on this stack: playing anyway (--no-wait)")
            return ready
        if mono_s() >= deadline:
            raise StackError(
                reach.unreached(
                    (
                        "a detector is ready but serves not every played camera"
                        if detector
                        else "no detector was ready"
                    )
                    + f" within {config.recorder.detector_wait_s:g} s "
                    "(recorder.detector_wait_s) to detect on the replay",
                    config.zenoh, prefix, PLAY_PRINCIPAL, linked=True, ready=frozenset(ready),
                )
                + "; --no-wait plays without waiting"
            )  # fmt: skip
        if not said:
            said = True
            progress(
                f"waiting up to {config.recorder.detector_wait_s:g} s for a detector to be "
                "ready (--no-wait plays at once)"
            )
        if stop.wait(READY_POLL_S):
            return ready


def served_cameras(bus: Bus, config: Config) -> set[str]:
    """The cameras of this stack that a detector worker serves now (its serving tokens, under
    the pool's prefix: services/detector/membership.py)."""
    prefix = config.stack.prefix
    pool = Keys(config.detector.pool_prefix or prefix)
    parts = (pool.pool_serving_parts(k) for k in bus.live_tokens(pool.all_pool_serving(), 1.0))
    robot = pool_name(prefix, "", pool.prefix)  # "" on the pool's own robot, "<prefix>/" else
    return {p[2].removeprefix(robot) for p in parts if p is not None and p[2].startswith(robot)}


def play(
    config: Config,
    path: Path,
    stop: threading.Event,
    progress: Progress,
    *,
    rate: float = 1.0,
    loop: bool = False,
    topics: Sequence[str] | None = None,
    wait: bool = True,
    bus: Bus | None = None,
) -> Played:
    """Publish the recording's frames, depth images and scans (play.py) until it ends (or ``stop``;
    ``loop``: again); with ``wait``, not before a detector is ready to see them. Each camera
    played is announced until then (play.py's announce_played). ``bus``: where to play (a
    session of the player's own, closed at the end, unless given)."""
    chosen = playable_topics(path, topics)
    recorded = recorded_cameras(config, path, chosen)
    keys = Keys(config.stack.prefix)
    with ExitStack() as closing:
        if bus is None:
            bus = ZenohBus(open_session(config.zenoh, config.principal(PLAY_PRINCIPAL)))
            closing.callback(bus.close)
        announcements = closing.enter_context(CameraAnnouncements(bus, keys, ANNOUNCED_SOURCE))
        _ready_to_play(
            config, bus, path, stop, progress, wait,
            lambda: announce_played(config, announcements, recorded, rate),
            lambda: set(recorded) <= served_cameras(bus, config),
        )  # fmt: skip
        played_keys = [keys.frame(c) for c in config.all_cameras]
        played_keys += [keys.depth(c) for c in config.all_cameras] + [keys.scan()]
        pubs = {key: bus.publisher(key, QoS.SENSOR) for key in played_keys}
        played = Played()
        while not stop.is_set():
            one_pass(config, path, chosen, rate, lambda key, b: pubs[key].put(b), stop, played)
            played.passes += 1
            depth = f"{played.depths} depth images, " if played.depths else ""
            progress(f"played {path}: {played.frames} frames, {depth}{played.scans} scans"
                     f" ({played.passes} pass{'es' if played.passes > 1 else ''})")  # fmt: skip
            if not loop:
                break
        return played
