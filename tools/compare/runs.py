"""A recorded run as compare.py needs it: detections per frame, commands, frame count.

Read from the JSON channels our recorder writes (services/recorder/channels.py): ``Detections``
(with the frame's sequence number, the detector's timings and the boxes' columns), read back
into the message itself, and ``Twist`` (with ``input_stamp_ns``). Detections are kept by frame:
the camera (read from the stack key they were recorded on) and the frame's sequence number,
which each camera numbers on its own. The first detections of each frame are kept (a looped
replay repeats them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from common.boxes import Boxes
from common.errors import DecodeError, RecordingError
from common.keys import camera_in_key
from common.messages import Detections, Header
from services.recorder.reading import Input, Recording, input_kind


@dataclass(frozen=True, slots=True)
class CommandRecord:
    """One velocity command as a recording holds it (the controller's is VelocityCommand)."""

    stamp_ns: int
    input_stamp_ns: int
    linear: float  # m/s forward
    angular: float  # rad/s about z


#: A frame of a run: its camera and its sequence number (each camera numbers its own frames).
FrameId = tuple[str, int]


@dataclass(slots=True)
class Run:
    path: Path
    frames: int = 0
    frame_span_s: float = 0.0  # the first frame's to the last's log time (every camera's)
    detections: dict[FrameId, Detections] = field(default_factory=dict)  # by (camera, seq)
    commands: list[CommandRecord] = field(default_factory=list)
    truncated: bool = False
    # Which model produced the detections: "model (backend/device/precision)", in the order
    # first seen (a run that changed model midway names both).
    detectors: list[str] = field(default_factory=list)


def detections_from_json(body: dict[str, Any]) -> Detections:
    """The ``Detections`` message a JSON channel holds (channels.to_json wrote it, its boxes'
    arrays as lists beside the other fields); DecodeError when it is not one."""
    try:
        h = body["header"]
        header = Header(
            stamp_ns=int(h["stamp_ns"]),
            frame_id=str(h["frame_id"]),
            seq=int(h["seq"]),
            source=str(h["source"]),
            mono_ns=int(h.get("mono_ns", 0)),
            boot_id=str(h.get("boot_id", "")),
        )
        tracks = body.get("track_ids")
        boxes = Boxes(
            xyxy=np.asarray(body["xyxy"], dtype=np.float32).reshape(-1, 4),
            scores=np.asarray(body["scores"], dtype=np.float32).reshape(-1),
            class_ids=np.asarray(body["class_ids"], dtype=np.int32).reshape(-1),
            track_ids=None if tracks is None else np.asarray(tracks, dtype=np.int32).reshape(-1),
            # Absent from recordings made before columns existed: none.
            columns=columns_from_json(body.get("columns") or {}),
        )
        return Detections(
            header=header,
            image_width=int(body["image_width"]),
            image_height=int(body["image_height"]),
            boxes=boxes,
            class_names=tuple(str(n) for n in body["class_names"]),
            timing_ms={str(k): float(v) for k, v in body.get("timing_ms", {}).items()},
            model=str(body.get("model", "")),
            backend=str(body.get("backend", "")),
            received_ns=int(body.get("received_ns", 0)),
            published_ns=int(body.get("published_ns", 0)),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise DecodeError(f"not a Detections message: {exc}") from exc


def columns_from_json(columns: dict[str, Any]) -> dict[str, npt.NDArray[Any]]:
    """Boxes' columns as channels.to_json wrote them, name -> list of values: JSON keeps no
    dtype, so a column of booleans comes back bool, one of integers int64, any other float64
    (null, a NaN or inf written as JSON, as NaN)."""
    if not isinstance(columns, dict):
        raise TypeError(f"columns must be a map, got {type(columns).__name__}")
    out: dict[str, npt.NDArray[Any]] = {}
    for name, values in columns.items():
        if values and all(type(v) is bool for v in values):
            out[name] = np.array(values, np.bool_)
        elif values and all(type(v) is int for v in values):
            out[name] = np.array(values, np.int64)
        else:
            out[name] = np.array([np.nan if v is None else v for v in values], np.float64)
    return out


def detector_name(body: dict[str, Any]) -> str:
    """``model (backend)`` as a Detections JSON message names them; "unknown" when it does not."""
    model, backend = str(body.get("model") or "unknown"), str(body.get("backend") or "")
    return f"{model} ({backend})" if backend else model


def command_from_json(body: dict[str, Any]) -> CommandRecord:
    try:
        return CommandRecord(
            stamp_ns=int(body["header"]["stamp_ns"]),
            input_stamp_ns=int(body.get("input_stamp_ns", 0)),
            linear=float(body["linear"][0]),
            angular=float(body["angular"][2]),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise DecodeError(f"not a Twist message: {exc}") from exc


def load_run(path: str | Path) -> Run:
    """The run recorded in ``path``; RecordingError when it holds no detections to compare."""
    run = Run(Path(path))
    bad = 0
    first_ns = last_ns = None
    with Recording(path) as rec:
        for record in rec.records():
            kind = record.stack_type
            try:
                if kind == "Detections" and record.channel.message_encoding == "json":
                    body = record.json()
                    dets = detections_from_json(body)
                    topic = record.channel.topic
                    camera = camera_in_key(topic) or topic
                    run.detections.setdefault((camera, dets.header.seq), dets)
                    detector = detector_name(body)
                    if detector not in run.detectors:
                        run.detectors.append(detector)
                elif kind == "Twist" and record.channel.message_encoding == "json":
                    run.commands.append(command_from_json(record.json()))
                elif input_kind(record) is Input.FRAME:
                    run.frames += 1
                    at = record.message.log_time
                    first_ns = at if first_ns is None else min(first_ns, at)
                    last_ns = at if last_ns is None else max(last_ns, at)
            except DecodeError:
                bad += 1
        run.truncated = rec.truncated
    if first_ns is not None and last_ns is not None:
        run.frame_span_s = (last_ns - first_ns) / 1e9
    if not run.detections:
        raise RecordingError(
            f"{path}: no detections to compare (this stack's recorder writes them as JSON on "
            f"<prefix>/detector/<camera>/detections; {bad} unreadable)"
        )
    return run
