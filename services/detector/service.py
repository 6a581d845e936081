"""The detector service: newest frame in, Detections out, with the frame's header."""

from __future__ import annotations

import json
import threading

import numpy as np
import numpy.typing as npt
import zenoh

from common.bus import QoS
from common.clock import BOOT_ID, now, wall_ns
from common.contracts import DetectorInfo
from common.errors import DecodeError, ImageError, ImageTooLarge
from common.frames import check_pixel_budget, frame_to_bgr
from common.freshness import FreshnessGate, Verdict
from common.messages import Detections, Frame, Header
from common.node import Node, Tally
from common.seqgaps import SeqGaps
from common.settings import Config, DetectorSettings
from services.detector.mailbox import Mailbox
from services.detector.pipeline import Detector
from services.detector.tracker import Tracker, tracker_clock
from services.detector.types import DetectionResult
from services.detector.variants import variant_of

_WAIT_S = 0.2  # how often the idle loop looks at the stop flag


def open_detector(s: DetectorSettings) -> tuple[Detector, str]:
    """Load the configured model (the default one, fetched if needed, when none is named) at
    its size and precision, or the fast profile's choice; with a note on what was chosen."""
    from services.detector.variants import open_prepared

    if s.profile == "fast":
        from services.detector.fast_profile import choose_fast

        variant, why = choose_fast(s)  # measured ahead: zstack fast-profile
        det, note = open_prepared(variant.settings(s))
        return det, f"{why}; {note}" if note else why
    return open_prepared(s)


def to_message(
    frame: Frame,
    result: DetectionResult,
    det: Detector,
    received_ns: int,
    track_ids: npt.NDArray[np.int32] | None,
) -> Detections:
    """The Detections message for ``frame``: its header, the result, the detector's stamps."""
    t = result.timing
    return Detections(
        header=frame.header,
        image_width=frame.width,
        image_height=frame.height,
        boxes=result.boxes.with_track_ids(track_ids),
        class_names=tuple(result.class_names),
        timing_ms={
            "preprocess": t.preprocess_ms,
            "inference": t.inference_ms,
            "postprocess": t.postprocess_ms,
        },
        model=det.model_path.name,
        backend=f"{det.backend.name}/{det.backend.device}/{det.backend.precision}",
        received_ns=received_ns,
        published_ns=wall_ns(),
    )


class DetectorHandlers:
    """What the detector does with a frame as it arrives: decode it, count it, and leave it in
    the mailbox that the detection loop takes the newest frame from."""

    def __init__(self, config: Config, tally: Tally) -> None:
        self.settings = config.detector
        self.tally = tally
        self.frame_key = tally.keys.frame(config.stack.camera)
        self.mailbox: Mailbox[Frame] = Mailbox()
        self.gaps = SeqGaps()

    def on_frame(self, payload: bytes) -> None:
        # Decode here, not in the loop: garbage must be counted even when a newer frame would
        # have replaced it in the mailbox before the loop looked at it; and an oversize frame
        # must never displace a real one there.
        counters = self.tally.counters
        counters.add("frames_in")
        try:
            frame = Frame.decode(payload)
            missed = self.gaps.observe(frame.header)
            if missed:
                counters.add("frames_missed", missed)
            check_pixel_budget(frame, self.settings.max_frame_pixels)
        except DecodeError as exc:
            self.tally.bad_input(self.frame_key, exc)
            return
        except ImageTooLarge as exc:
            self.tally.reject("frames_oversize", str(exc), key=self.frame_key)
            return
        if self.mailbox.put(frame):
            counters.add("dropped")


def run(config: Config, stop: threading.Event) -> int:
    """Detect on the newest frame until ``stop`` is set."""
    s = config.detector
    with Node("detector", config, counters_period_s=s.counters_period_s) as node:
        detector, note = open_detector(s)
        b = detector.backend
        node.log.info(
            "model %s on %s (%s, %s, input %d)%s",
            detector.model_path,
            b.name,
            b.device,
            b.precision,
            detector.info.input_height,
            f": {note}" if note else "",
        )
        handlers = DetectorHandlers(config, node)
        frame_key, mailbox = handlers.frame_key, handlers.mailbox
        tracker = Tracker(config.tracker) if config.tracker.enabled else None
        sub = node.subscribe(frame_key, handlers.on_frame)
        pub = node.publisher(node.keys.detections(config.stack.camera), QoS.PERCEPTION)
        gate = FreshnessGate(s.max_frame_age_s, config.stack.clock_tolerance_s, BOOT_ID)
        info = json.dumps(
            DetectorInfo(
                model=detector.model_path.name,
                classes=list(detector.names),
                backend=b.name,
                device=b.device,
                precision=b.precision,
                variant=variant_of(detector),
                note=note,
            )
        )
        info_key = node.keys.detector_info(config.stack.camera)
        queryable = node.session.declare_queryable(
            info_key, lambda q: q.reply(info_key, info, encoding=zenoh.Encoding.APPLICATION_JSON)
        )
        # Warm the backend up before announcing readiness: the first run allocates.
        detector.detect(np.full((480, 640, 3), 114, np.uint8))
        node.ready()
        try:
            while not stop.is_set():
                node.publish_counters()
                item = mailbox.take(_WAIT_S)
                if item is None:
                    continue
                frame, received_ns = item
                # Judged as it leaves the mailbox: a frame that waited out a pause (or was
                # stamped wrong, or sent again) is not worth a detection nobody may act on.
                verdict, age = gate.check(frame.header, now())
                if verdict is not Verdict.FRESH:
                    node.reject(f"frames_{verdict}", f"{verdict} frame ({age:.2f} s old) dropped")
                    continue
                try:
                    image = frame_to_bgr(frame, s.max_frame_pixels)
                except ImageError as exc:
                    node.bad_input(frame_key, exc)
                    continue
                result = detector.detect(image)
                if not result.output_sane:
                    # Zero boxes from a broken model are no verdict: publish nothing, so that
                    # the controller's detection timeout stops the robot.
                    node.reject(
                        "nonfinite_outputs",
                        f"the model's output for frame {frame.header.seq} is not finite (NaN, "
                        "infinity or a magnitude over 1e6): no detections published",
                    )
                    continue
                track_ids = (
                    None
                    if tracker is None
                    else _track(node, tracker, result, frame.header, received_ns)
                )
                pub.put(to_message(frame, result, detector, received_ns, track_ids).encode())
                node.counters.add("detections_out")
        finally:
            sub.undeclare()
            queryable.undeclare()
            detector.close()
    return 0


def _track(
    node: Node, tracker: Tracker, result: DetectionResult, header: Header, received_ns: int
) -> npt.NDArray[np.int32]:
    """Track ids for ``result``; a frame whose stamp jumped is counted, its ids left at -1."""
    ignored, resets = tracker.ignored_frames, tracker.resets
    at, arrival = tracker_clock(
        header.stamp_ns, header.mono_ns, header.boot_id, received_ns, BOOT_ID
    )
    ids = tracker.update(result.boxes, at, arrival)
    if tracker.ignored_frames > ignored:
        node.reject("tracker_stamp_jumps", "frame stamp jumped: the tracker ignored it")
    if tracker.resets > resets:
        node.reject("tracker_resets", "frame stamps jumped for good: tracks restarted")
    return ids
