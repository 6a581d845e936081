"""The detection loop's work (:class:`Rounds`): a round of frames, one per waiting camera, run
through the model as one batch, each camera's detections published on its own key. Time is
read from an injected clock (the freshness gate's ``now``, ``published_ns``)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from common.bus import Declared
from common.clock import BOOT_ID, SYSTEM_CLOCK, Clock
from common.counters import BAD_INPUT, per_camera
from common.errors import ImageError
from common.frames import frame_to_bgr
from common.freshness import FreshnessGate, Verdict
from common.keys import Keys
from common.messages import ControllerStatus, Detections, Frame, Header
from common.node import Node, Put, Tally
from common.pool_rule import label, pool_name, robot_label
from perception import (
    DetectionResult,
    Detector,
    KalmanTracker,
    Tracker,
    appearance,
    new_tracker,
    tracker_clock,
)
from services.detector import contract
from services.detector.attention import Attention
from services.detector.counting import count_for, reject_for
from services.detector.depth_stage import DepthStage
from services.detector.motion import RobotTurns
from services.detector.schedule import Waiting
from stack.config import Config


def to_message(
    frame: Frame,
    result: DetectionResult,
    det: Detector,
    received_ns: int,
    boxes: Boxes,
    published_ns: int,
    depth_ms: float | None = None,
    worker: str = "",
) -> Detections:
    """The Detections message for ``frame``: its header, the result (its ``boxes`` with their
    track ids and any depth columns), the detector's stamps; ``depth_ms``: the depth stage's
    time, when it ran (``timing_ms["depth"]``)."""
    t = result.timing
    timing = {
        "preprocess": t.preprocess_ms,
        "inference": t.inference_ms,
        "postprocess": t.postprocess_ms,
    }
    if depth_ms is not None:
        timing["depth"] = depth_ms
    return Detections(
        header=frame.header,
        image_width=frame.width,
        image_height=frame.height,
        boxes=boxes,
        class_names=tuple(result.class_names),
        timing_ms=timing,
        model=det.model_path.name,
        backend=f"{det.backend.name}/{det.backend.device}/{det.backend.precision}",
        received_ns=received_ns,
        published_ns=published_ns,
        worker=worker,
    )


@dataclass(slots=True)
class CameraOutput:
    """What the detector keeps per camera: its frames' freshness (replays are judged per
    camera), its own tracker (track ids never cross cameras) and its detections' publisher."""

    camera: str
    frame_key: str
    gate: FreshnessGate
    tracker: Tracker | KalmanTracker | None
    put: Put
    # The camera's robot (its key prefix) and field of view: the Kalman tracker takes that
    # robot's turn out of its predictions (0: not known, no turn taken out).
    prefix: str = ""
    hfov_deg: float = 0.0
    last_at: float | None = None  # the capture time of the last frame tracked (s)


def camera_outputs(
    config: Config,
    frame_keys: Mapping[str, str],
    put_for: Callable[[str], Put],
    prefix: str = "",
    hfov_deg: float = 0.0,
) -> dict[str, CameraOutput]:
    """Each camera's output: a freshness gate, a tracker of ``tracker.kind`` when
    ``tracker.enabled``, and ``put_for(camera)`` to publish its detections with; ``prefix``
    and ``hfov_deg``: the cameras' robot and field of view (for the tracker's ego-rotation)."""
    s = config.detector
    return {
        cam: CameraOutput(
            camera=cam,
            frame_key=key,
            gate=FreshnessGate(s.max_frame_age_s, config.stack.clock_tolerance_s, BOOT_ID),
            tracker=new_tracker(config.tracker) if config.tracker.enabled else None,
            put=put_for(cam),
            prefix=prefix,
            hfov_deg=hfov_deg,
        )
        for cam, key in frame_keys.items()
    }


class Rounds:
    """The detection loop's work: take a round of frames, one per waiting camera, run them
    through the model as one batch, and publish each camera's detections with its frame's
    header on its own key. Counted in all and per camera; a round's size is counted as
    ``batches`` (rounds run) and ``batched_frames`` (frames in them): their ratio is the mean
    batch size. With ``attention``, each camera's published detections are its sightings, the
    frames are counted by why the round took them, and which cameras have priority is a
    gauge (services/detector/attention.py). With ``depth``, a frame of a camera with depth is
    paired with its depth frame as its detections are built, after the model ran, and they
    get the depth columns (services/detector/depth_stage.py)."""

    def __init__(
        self,
        config: Config,
        tally: Tally,
        detector: Detector,
        outputs: dict[str, CameraOutput],
        clock: Clock = SYSTEM_CLOCK,
        attention: Attention | None = None,
        depth: DepthStage | None = None,
        worker: str = "",
        turns: RobotTurns | None = None,
    ) -> None:
        self.settings = config.detector
        self.worker = worker  # named in every Detections (the pool judges members by it)
        self.turns = turns  # each robot's turn by its commands (the Kalman tracker's)
        self.tally = tally
        self.detector = detector
        self.outputs = outputs
        self.clock = clock
        self.attention = attention
        self.depth = depth
        self._priority: frozenset[str] = frozenset()
        self._floor_held = 0  # attention's floor_held, as counted

    def run(self, waiting: list[Waiting[Frame]]) -> None:
        self._run(waiting)
        if self.attention is not None:
            self._gauge_priority(self.attention.priority())
            held = self.attention.floor_held
            if held != self._floor_held:
                self.tally.counters.add(contract.ATTENTION_FLOOR_HELD, held - self._floor_held)
                self._floor_held = held

    def _gauge_priority(self, now: frozenset[str]) -> None:
        """``attention_priority`` (per camera: 1 while it has priority) moved to ``now``."""
        if now == self._priority:
            return
        counters = self.tally.counters
        for cam in now - self._priority:
            counters.add(per_camera(contract.ATTENTION_PRIORITY, cam), 1)
        for cam in self._priority - now:
            counters.add(per_camera(contract.ATTENTION_PRIORITY, cam), -1)
        counters.add(contract.ATTENTION_PRIORITY, len(now) - len(self._priority))
        self._priority = now

    def _run(self, waiting: list[Waiting[Frame]]) -> None:
        ready: list[tuple[CameraOutput, Frame, int, npt.NDArray[np.uint8]]] = []
        for w in waiting:
            if w.reason:
                count_for(self.tally, w.camera, contract.taken_for(w.reason))
            out, frame = self.outputs[w.camera], w.item
            # Judged as it leaves the slot: a frame that waited out a pause (or was stamped
            # wrong, or sent again) is not worth a detection nobody may act on.
            verdict, age = out.gate.check(frame.header, self.clock.now())
            if verdict is not Verdict.FRESH:
                reject_for(
                    self.tally,
                    w.camera,
                    contract.frames_judged(verdict),
                    f"{verdict} frame from {w.camera} ({age:.2f} s old) dropped",
                    out.frame_key,
                )
                continue
            try:
                image = frame_to_bgr(frame, self.settings.max_frame_pixels)
            except ImageError as exc:
                self.tally.bad_input(out.frame_key, exc)
                self.tally.counters.add(per_camera(BAD_INPUT, w.camera))
                continue
            ready.append((out, frame, w.received_ns, image))
            if self.depth is not None:
                self.depth.hold(w.camera, frame.header)
        if not ready:
            return
        results = self.detector.detect_batch([image for *_, image in ready])
        self.tally.counters.add(contract.BATCHES)
        self.tally.counters.add(contract.BATCHED_FRAMES, len(ready))
        for (out, frame, received_ns, image), result in zip(ready, results, strict=True):
            self._publish(out, frame, received_ns, result, image)

    def _publish(
        self,
        out: CameraOutput,
        frame: Frame,
        received_ns: int,
        result: DetectionResult,
        image: npt.NDArray[np.uint8],
    ) -> None:
        if not result.output_sane:
            # Zero boxes from a broken model are no verdict: publish nothing, so that the
            # controller's detection timeout stops the robot.
            reject_for(
                self.tally,
                out.camera,
                contract.NONFINITE_OUTPUTS,
                f"the model's output for frame {frame.header.seq} from {out.camera} is not "
                "finite (NaN, infinity or a magnitude over 1e6): no detections published",
                out.frame_key,
            )
            return
        track_ids = (
            None
            if out.tracker is None
            else _track(self.tally, out, result, frame.header, received_ns, image, self.turns)
        )
        boxes, depth_ms = result.boxes.with_track_ids(track_ids), None
        if self.depth is not None:
            size = (frame.width, frame.height)
            boxes, depth_ms = self.depth.measure(out.camera, frame.header, size, boxes)
        msg = to_message(
            frame, result, self.detector, received_ns, boxes, self.clock.wall_ns(), depth_ms,
            self.worker,
        )  # fmt: skip
        out.put(msg.encode())
        count_for(self.tally, out.camera, contract.DETECTIONS_OUT)
        if self.attention is not None:
            self.attention.saw(out.camera, result.class_names)


def heed_controller(
    tally: Tally, attention: Attention, prefix: str = "", pool_prefix: str = ""
) -> Callable[[bytes], None]:
    """The handler of robot ``prefix``'s controller status (``Keys(prefix).
    controller_status()``; by default the worker's own robot's): its locked camera, by its
    label in the pool under ``pool_prefix`` (common/pool_rule.py), and target classes to
    ``attention``; garbage counted as bad input and dropped."""
    prefix = prefix or tally.keys.prefix
    pool_prefix = pool_prefix or tally.keys.prefix
    key = Keys(prefix).controller_status()
    robot = robot_label(prefix, pool_prefix)

    def on_status(payload: bytes) -> None:
        status = tally.decode(key, ControllerStatus.decode, payload)
        if status is not None:
            cam = label(pool_name(prefix, status.camera, pool_prefix)) if status.camera else ""
            attention.controller(cam, status.target_classes, robot)

    return on_status


def heed_controllers(node: Node, config: Config, attention: Attention) -> list[Declared]:
    """Subscribe ``attention`` to the controller status of every robot the worker serves
    (``detector.prefixes``; empty: its own robot's)."""
    s = config.detector
    pool_prefix = s.pool_prefix or config.stack.prefix
    return [
        node.subscribe(
            Keys(prefix).controller_status(), heed_controller(node, attention, prefix, pool_prefix)
        )
        for prefix in s.prefixes or (config.stack.prefix,)
    ]


def _track(
    tally: Tally,
    out: CameraOutput,
    result: DetectionResult,
    header: Header,
    received_ns: int,
    image: npt.NDArray[np.uint8],
    turns: RobotTurns | None,
) -> npt.NDArray[np.int32]:
    """Track ids for ``result`` from its camera's tracker; a frame whose stamp jumped is
    counted, its ids left at -1. The Kalman tracker also gets each box's colour (from
    ``image``) and how far the camera's robot turned since its last frame (by ``turns``: a
    frame from this host only, tracked on its monotonic stamp)."""
    tracker = out.tracker
    assert tracker is not None
    ignored, resets = tracker.ignored_frames, tracker.resets
    at, arrival = tracker_clock(
        header.stamp_ns, header.mono_ns, header.boot_id, received_ns, BOOT_ID
    )
    if isinstance(tracker, KalmanTracker):
        turned = 0.0
        if turns is not None and arrival is None and out.last_at is not None:
            turned = turns.turned(out.prefix, out.last_at, at)
        width = image.shape[1]
        focal = width / 2 / math.tan(math.radians(out.hfov_deg) / 2) if out.hfov_deg > 0 else 0.0
        ids = tracker.update(
            result.boxes, at, arrival, turned_rad=turned, focal_px=focal,
            image_width=width, features=appearance(image, result.boxes.xyxy),
        )  # fmt: skip
    else:
        ids = tracker.update(result.boxes, at, arrival)
    out.last_at = at
    if tracker.ignored_frames > ignored:
        reject_for(
            tally,
            out.camera,
            contract.TRACKER_STAMP_JUMPS,
            "frame stamp jumped: the tracker ignored it",
            out.frame_key,
        )
    if tracker.resets > resets:
        reject_for(
            tally,
            out.camera,
            contract.TRACKER_RESETS,
            "frame stamps jumped for good: tracks restarted",
            out.frame_key,
        )
    return ids
