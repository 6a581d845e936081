"""The detector service's wiring: the newest frame of every camera it serves in, each camera's
Detections out, with its frame's header, on its own key; several cameras' frames batched
(docs/detector.md, "Several cameras"). Start-up (the model, the batch, the info queryables) and
the loop are here; what the loop does is elsewhere: the handlers (services/detector/handlers.py),
the rounds (services/detector/rounds.py) and the pool membership by which several workers divide
the cameras (services/detector/membership.py, over services/detector/pool.py)."""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import ParamSpec, TypeVar

import numpy as np

from common.bus import Declared, QoS, undeclare_all
from common.contracts import DetectorInfo
from common.keys import Keys
from common.node import Node
from perception import Detector, load, variant_of
from perception import measure_batch as measure
from services.detector.attention import Attention
from services.detector.capacity import Capacity
from services.detector.capacity import measure as measure_capacity
from services.detector.contract import BATCHED_FRAMES, DetectorSettings
from services.detector.fairness import RobotFair
from services.detector.handlers import DetectorHandlers
from services.detector.membership import PoolMember
from services.detector.motion import RobotTurns, heed_commands
from services.detector.pool import PoolCamera
from services.detector.rounds import CameraOutput, Rounds, camera_outputs, heed_controllers
from stack.config import Config

P = ParamSpec("P")
R = TypeVar("R")

_WAIT_S = 0.2  # how often the idle loop looks at the stop flag (and the pool's membership)


def open_detector(s: DetectorSettings, max_batch: int = 1) -> tuple[Detector, str]:
    """Load what ``zstack prepare`` made for ``s`` (the model at its size and precision, or the
    fast profile's choice), for batches of up to ``max_batch`` frames, with a note on what was
    chosen; builds and measures nothing (NotPrepared names what is missing)."""
    return load(s, max_batch)


def served_batch(config: Config) -> int:
    """The most frames one round takes: ``detector.max_batch`` (a round takes one frame per
    camera with one waiting, so one camera always runs batches of 1). The cameras are those
    announced at run time, not the config's."""
    return config.detector.max_batch


def run(config: Config, stop: threading.Event, worker: str = "detector") -> int:
    """Detect on the newest frame of every camera this worker serves until ``stop`` is set;
    ``worker``: its one name (one of ``Config.detector_services``), its service, pool id and
    principal. Its cameras are those announced on the bus that the pool gives it
    (services/detector/membership.py); each one's detections go on its own robot's keys.

    What start-up opens is closed in the reverse order, however it ends (a stop while
    measuring included): the pool's membership, the controllers' status subscriptions, the
    info queryables, the model, the node."""
    s = config.detector
    try:
        with ExitStack() as closing:
            node = closing.enter_context(
                Node(worker, config, counters_period_s=s.counters_period_s)
            )
            model = open_model(closing, s, served_batch(config), node.log, stop)
            _serve(closing, config, stop, worker, node, model)
    except _StoppedEarly:
        logging.getLogger(worker).info("stopped while starting")
    return 0


class _StoppedEarly(Exception):
    """A stop asked for while the worker was still measuring (its batch, its capacity)."""


def _until_stopped(stop: threading.Event, run: Callable[P, R]) -> Callable[P, R]:
    """``run``, ended with _StoppedEarly at its next call once ``stop`` is set: start-up's
    timed runs (batch sizes, capacity) take many seconds on a busy CPU, and a stop must not
    wait for them (the supervisor kills what has not ended within ``stop_timeout_s``)."""

    def call(*args: P.args, **kwargs: P.kwargs) -> R:
        if stop.is_set():
            raise _StoppedEarly
        return run(*args, **kwargs)

    return call


@dataclass
class OpenModel:
    """The model a worker serves with: the detector, the note on what was chosen, and the
    frames a round takes."""

    detector: Detector
    note: str
    per_round: int

    def close(self) -> None:
        self.detector.close()


def open_model(
    closing: ExitStack,
    s: DetectorSettings,
    served: int,
    log: logging.Logger,
    stop: threading.Event,
) -> OpenModel:
    """Load what ``zstack prepare`` made for ``s``, for rounds of up to ``served`` frames, and
    settle its batch (:func:`settle_batch`, which may open it again); said in the log, and
    closed by ``closing`` (the one open then, should the batch's settling fail)."""
    detector, note = open_detector(s, served)
    model = OpenModel(detector, note, served)
    closing.callback(model.close)  # whichever detector is open then
    b = detector.backend
    log.info(
        "model %s on %s (%s, %s, input %d)%s",
        detector.model_path, b.name, b.device, b.precision, detector.info.input_height,
        f": {note}" if note else "",
    )  # fmt: skip
    per_round = round_size(detector, served, log)
    model.detector, model.note, model.per_round = settle_batch(
        detector, note, per_round, s, log, stop
    )
    return model


def _serve(
    closing: ExitStack,
    config: Config,
    stop: threading.Event,
    worker: str,
    node: Node,
    model: OpenModel,
) -> None:
    s, detector, per_round = config.detector, model.detector, model.per_round
    b = detector.backend  # the one that runs (settle_batch may have opened it again)
    handlers = DetectorHandlers(config, node, node.clock, frame_keys={})
    info = json.dumps(
        DetectorInfo(
            model=detector.model_path.name,
            classes=list(detector.names),
            backend=b.name,
            device=b.device,
            precision=b.precision,
            variant=variant_of(detector),
            note=model.note,
        )
    )
    cameras = ServedCameras(config, node, handlers, info)
    closing.callback(cameras.close)
    # Attention when short of capacity (services/detector/attention.py): the rounds'
    # order, fed by the controller's status and each camera's detections.
    attention = Attention(
        node.clock,
        s.attention_floor_hz,
        s.attention_hold_s,
        s.attention,
        floor_share=s.attention_floor_share,
    )
    status_subs = heed_controllers(node, config, attention)  # each robot's controller
    closing.callback(undeclare_all, status_subs)
    # Each robot's turn by its commands, for the Kalman tracker (services/detector/motion.py).
    turns = RobotTurns()
    command_subs = heed_commands(node, config, turns)
    closing.callback(undeclare_all, command_subs)
    rounds = Rounds(
        config, node, detector, cameras.outputs, node.clock, attention, handlers.depth, worker,
        turns,
    )  # fmt: skip
    capacity = _warm_up(detector, per_round, s, node, stop)
    pool = PoolMember(
        node,
        worker,
        handlers,
        capacity=capacity,
        input_size=detector.info.input_height,
        backend=f"{b.name}/{b.device}/{b.precision}",
        max_batch=per_round,
        on_gained=cameras.gained,
        on_lost=cameras.lost,
        stopping=stop.is_set,
    )
    pool.join()
    closing.callback(pool.close)
    pool.start_stall_watch()
    node.ready()
    # Between robots first, then each robot's cameras in attention's order
    # (services/detector/fairness.py).
    order = RobotFair(attention)
    while not stop.is_set():
        pool.beat()
        pool.settle()
        pool.audit()
        node.publish_counters()
        waiting = handlers.slots.take(per_round, _WAIT_S, order)
        if waiting:
            before, start = node.counters.get(BATCHED_FRAMES), node.clock.mono_s()
            rounds.run(waiting)
            pool.observe_round(
                node.counters.get(BATCHED_FRAMES) - before, node.clock.mono_s() - start
            )


def _warm_up(
    detector: Detector, per_round: int, s: DetectorSettings, node: Node, stop: threading.Event
) -> Capacity:
    """Warm the backend up before announcing readiness (the first run allocates, and each
    batch size may: a CUDA graph, an OpenVINO shape), then measure the capacity unless
    ``detector.capacity_hz`` fixes it; _StoppedEarly once ``stop`` is set."""
    warm = np.full((480, 640, 3), 114, np.uint8)
    detect = _until_stopped(stop, detector.detect_batch)
    for size in sorted({1, per_round}):
        detect([warm] * size)
    measured = 0.0
    if s.capacity_hz == 0:
        measured = measure_capacity(
            lambda: len(detect([warm] * per_round)), s.batch_probe_runs, node.clock
        )
    capacity = Capacity(measured, s, node.clock.mono_s())
    node.log.info(
        "capacity %.1f frames/s (%s)",
        capacity.announced,
        "detector.capacity_hz" if capacity.fixed else "measured",
    )
    return capacity


class ServedCameras:
    """What the worker keeps for each camera it comes to serve (the pool member's
    ``on_gained`` and ``on_lost``): its output (freshness gate, tracker, and a publisher on
    the detections key of the camera's own robot) and, while it serves it, the detector's
    info queryable on that robot's key. ``outputs`` is what the rounds publish through."""

    def __init__(self, config: Config, node: Node, handlers: DetectorHandlers, info: str) -> None:
        self.config = config
        self.node = node
        self.handlers = handlers
        self.info = info
        self.outputs: dict[str, CameraOutput] = {}
        self.queryables: dict[str, Declared] = {}

    def gained(self, name: str, cam: PoolCamera) -> None:
        robot = Keys(cam.prefix)
        if name not in self.outputs:
            put = self.node.publisher(robot.detections(cam.camera), QoS.PERCEPTION).put
            frame_keys = {name: self.handlers.frame_keys[name]}
            self.outputs.update(
                camera_outputs(self.config, frame_keys, lambda _: put, cam.prefix, cam.hfov_deg)
            )
        key = robot.detector_info(cam.camera)
        self.queryables[name] = _info_queryable(self.node, key, self.info)

    def lost(self, name: str) -> None:
        queryable = self.queryables.pop(name, None)
        if queryable is not None:
            queryable.undeclare()

    def close(self) -> None:
        for name in list(self.queryables):
            self.lost(name)


def settle_batch(
    detector: Detector,
    note: str,
    per_round: int,
    s: DetectorSettings,
    log: logging.Logger,
    stop: threading.Event | None = None,
) -> tuple[Detector, str, int]:
    """With ``batch_choice`` "measured" and rounds of several frames on a model of dynamic
    batch: time the batch sizes and keep the one that serves frames fastest
    (perception/batching.py). When that is 1, the model is opened again for batch 1:
    the fastest batch-1 session, and the buffers the large batches took given back."""
    if per_round == 1 or s.batch_choice != "measured" or detector.info.batch_size is not None:
        return detector, note, per_round
    detect = detector.detect_batch if stop is None else _until_stopped(stop, detector.detect_batch)
    choice = measure(detect, per_round, s.batch_probe_runs, s.batch_min_gain)
    log.info("%s", choice.describe())
    if choice.size == 1:
        detector.close()
        detector, note = open_detector(s, 1)
    return detector, note, choice.size


def round_size(detector: Detector, served: int, log: logging.Logger) -> int:
    """Frames per round: ``served``, cut to a fixed-batch model's batch (which a smaller
    round is padded to), said in one line when the model's batch is not ``served``."""
    fixed = detector.info.batch_size
    if fixed is None or fixed == served:
        return served
    log.info(
        "the model takes a fixed batch of %d: rounds of up to %d frame(s) (detector.max_batch "
        "and the cameras allow %d), each run as one batch of %d",
        fixed,
        min(served, fixed),
        served,
        fixed,
    )
    return min(served, fixed)


def _info_queryable(node: Node, key: str, info: str) -> Declared:
    return node.bus.serve(key, lambda _key, _query: info.encode())
