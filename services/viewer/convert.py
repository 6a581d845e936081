"""Our messages as Foxglove's: the camera image, its annotations, the scan and the plottable
figures. Pure: messages in, Foxglove messages (or JSON-able dicts) out; no bus, no server.

Frames: the robot's base is ``base_link`` (x forward, y left, REP 103); the stack's scan is
taken in it (the controller reads its angles as bearings from the robot's heading).
"""

from __future__ import annotations

from typing import Any, cast

import cv2
import numpy as np
from foxglove.messages import (
    Color,
    CompressedImage,
    ImageAnnotations,
    LaserScan,
    Point2,
    PointsAnnotation,
    PointsAnnotationType,
    TextAnnotation,
    Timestamp,
)

from common.annotate import class_colour, column_labels
from common.contracts import MetricsAnswer
from common.counters import BAD_INPUT
from common.errors import ImageError
from common.frames import frame_to_bgr
from common.images import Image
from common.messages import ControllerStatus, Detections, Frame, Twist
from common.messages import LaserScan as StackScan

ROBOT_FRAME = "base_link"
BOX_THICKNESS_PX = 2.0
LOCKED_THICKNESS_PX = 5.0
LOCKED_COLOUR = Color(r=1.0, g=0.1, b=0.1, a=1.0)  # the controller's target stands out in red
LABEL_FONT_PX = 14.0
# A glyph's width as a share of the font size: enough to keep a label inside the image.
GLYPH_WIDTH = 0.6


def label_position(x1: float, y1: float, text: str, width: float) -> tuple[float, float]:
    """Where a box's label goes. Foxglove's TextAnnotation ``position`` is the text's
    *bottom-left* corner: above the box's top edge when there is room, else just inside the
    box (a box touching the image's top, as the followed person at follow distance); moved
    left so that it ends inside the image."""
    y = y1 if y1 >= LABEL_FONT_PX else y1 + LABEL_FONT_PX
    x = max(0.0, min(x1, width - GLYPH_WIDTH * LABEL_FONT_PX * len(text)))
    return x, y


_BLACK = Color(r=0.0, g=0.0, b=0.0, a=1.0)


#: The last second a Foxglove timestamp holds (its seconds are a uint32: early 2106).
MAX_STAMP_S = 2**32 - 1


def stamp(ns: int) -> Timestamp:
    """A Foxglove timestamp from our nanoseconds since the epoch. Raises ValueError for a
    stamp past ``MAX_STAMP_S`` (a header may hold any uint64; Foxglove's cannot)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    if not 0 <= sec <= MAX_STAMP_S:
        raise ValueError(f"stamp {ns} ns is past what a Foxglove timestamp holds")
    return Timestamp(sec, nsec)


def scaled_size(width: int, height: int, max_width: int) -> tuple[int, int]:
    """The size an image is sent at: ``width`` at most ``max_width`` (0: unchanged), the
    aspect kept."""
    if max_width == 0 or width <= max_width:
        return width, height
    return max_width, max(1, round(height * max_width / width))


def compressed_image(frame: Frame, jpeg_quality: int, max_width: int) -> CompressedImage:
    """``frame`` as a JPEG ``CompressedImage`` no wider than ``max_width`` (0: its own width).
    Raises ImageError if the frame's pixels cannot be read or encoded."""
    image = frame_to_bgr(frame)
    size = scaled_size(frame.width, frame.height, max_width)
    if size != (frame.width, frame.height):
        image = cast(Image, cv2.resize(image, size, interpolation=cv2.INTER_AREA))
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    if not ok:
        raise ImageError(f"frame {frame.header.seq}: cannot encode as JPEG")
    return CompressedImage(
        timestamp=stamp(frame.header.stamp_ns),
        frame_id=frame.header.frame_id,
        data=jpeg.tobytes(),
        format="jpeg",
    )


def _colour(class_id: int) -> Color:
    b, g, r = class_colour(class_id)  # the same colours as the detector's saved images
    return Color(r=r / 255, g=g / 255, b=b / 255, a=1.0)


def label(name: str, score: float, track_id: int, locked: bool, columns: str = "") -> str:
    """What a box says: ``person 0.87 #3``, with ``LOCKED`` before the controller's target
    and the box's columns after (``distance_m=2.41``: common.annotate.column_labels)."""
    text = f"{name} {score:.2f}" + (f" #{track_id}" if track_id >= 0 else "")
    text += f" {columns}" if columns else ""
    return f"LOCKED {text}" if locked else text


def image_annotations(
    dets: Detections, width: int, height: int, locked_track: int
) -> ImageAnnotations:
    """Each detection as a box outline and a label on a ``width`` x ``height`` image (the
    size the image is sent at; the boxes are scaled from the detector's image); the label
    names every column with its value (``distance_m=2.41``). The box whose
    track id is ``locked_track`` (the controller's target; -1: none) is drawn thicker, in red."""
    ts = stamp(dets.header.stamp_ns)
    sx, sy = width / dets.image_width, height / dets.image_height
    boxes = dets.boxes
    xyxy = (boxes.xyxy.astype(np.float64) * np.array([sx, sy, sx, sy])).tolist()
    n = len(xyxy)
    tracks = boxes.track_ids.tolist() if boxes.track_ids is not None else [-1] * n
    extras = column_labels(boxes.columns, n)
    points: list[PointsAnnotation] = []
    texts: list[TextAnnotation] = []
    for (x1, y1, x2, y2), name, score, cid, tid, extra in zip(
        xyxy, dets.class_names, boxes.scores.tolist(), boxes.class_ids.tolist(), tracks, extras,
        strict=True,
    ):  # fmt: skip
        locked = tid >= 0 and tid == locked_track
        colour = LOCKED_COLOUR if locked else _colour(cid)
        corners = [Point2(x=x1, y=y1), Point2(x=x2, y=y1), Point2(x=x2, y=y2), Point2(x=x1, y=y2)]
        points.append(
            PointsAnnotation(
                timestamp=ts,
                type=PointsAnnotationType.LineLoop,
                points=corners,
                outline_color=colour,
                thickness=LOCKED_THICKNESS_PX if locked else BOX_THICKNESS_PX,
            )
        )
        text = label(name, score, tid, locked, extra)
        lx, ly = label_position(x1, y1, text, width)
        texts.append(
            TextAnnotation(
                timestamp=ts,
                position=Point2(x=lx, y=ly),
                text=text,
                font_size=LABEL_FONT_PX,
                text_color=_BLACK,
                background_color=colour,
            )
        )
    return ImageAnnotations(timestamp=ts, points=points, texts=texts)


def laser_scan(scan: StackScan) -> LaserScan:
    """The scan in the robot's frame. Rays with nothing in range (inf) or invalid (NaN) stay
    as they are: Foxglove draws no point for them."""
    n = len(scan.ranges)
    return LaserScan(
        timestamp=stamp(scan.header.stamp_ns),
        frame_id=ROBOT_FRAME,
        start_angle=scan.angle_min,
        end_angle=scan.angle_min + scan.angle_increment * (n - 1),
        ranges=scan.ranges.astype(np.float64).tolist(),
    )


def twist_json(twist: Twist) -> dict[str, Any]:
    """The command as plottable numbers: m/s forward and rad/s counter-clockwise."""
    return {
        "linear": twist.linear[0],
        "angular": twist.angular[2],
        "input_stamp_ns": twist.input_stamp_ns,
        "source": twist.header.source,
    }


def status_json(status: ControllerStatus) -> dict[str, Any]:
    return {
        "mode": status.mode,
        "state": status.state,
        "target": status.target,
        "track_id": status.track_id,
        "locked": status.track_id >= 0,
        "reason": status.reason,
    }


def metrics_json(answer: MetricsAnswer) -> dict[str, Any]:
    """The metrics service's answer without its timeline (plotted live instead): FPS, drops,
    bad input, the depth images taken and missed, and each stage's latency percentiles in
    ms."""
    counters = answer["counters"]
    return {
        "fps": answer["fps"],
        "detections_per_frame": answer["detections_per_frame"],
        "dropped_frames": answer["dropped_frames"],
        "drop_rate": answer["drop_rate"],
        "bad_input": sum(v for k, v in counters.items() if k.endswith(f".{BAD_INPUT}")),
        "depth_frames": answer.get("depth_frames", 0),
        "depth_unpaired": answer.get("depth_unpaired", 0),
        "latency_ms": answer["latency_ms"],
    }
