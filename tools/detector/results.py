"""How ``detect`` writes a result: one JSON object per image or video frame, or one text line.

The JSON form (docs/detector.md): ``image`` (the path or the video/device it came from),
``frame`` (a video's or device's frame index from 0; images have none), ``width``, ``height``,
``detections`` (``class_id``, ``class_name``, ``score``, ``bbox_xyxy`` in image pixels) and
``timing_ms`` (``preprocess``, ``inference``, ``postprocess``).
"""

from __future__ import annotations

import json
from typing import Any

from perception import DetectionResult


def result_record(source: str, result: DetectionResult, frame: int | None = None) -> dict[str, Any]:
    """The JSON object for one image, or for frame ``frame`` of a video or device."""
    detections = [
        {
            "class_id": cid,
            "class_name": name,
            "score": round(score, 4),
            "bbox_xyxy": [round(v, 2) for v in box],
        }
        for cid, name, score, box in zip(
            result.class_ids.tolist(),
            result.class_names,
            result.scores.tolist(),
            result.xyxy.tolist(),
            strict=True,
        )
    ]
    t = result.timing
    where: dict[str, Any] = {"image": source}
    if frame is not None:
        where["frame"] = frame
    return {
        **where,
        "width": result.image_width,
        "height": result.image_height,
        "detections": detections,
        "timing_ms": {
            "preprocess": round(t.preprocess_ms, 3),
            "inference": round(t.inference_ms, 3),
            "postprocess": round(t.postprocess_ms, 3),
        },
    }


def result_json(source: str, result: DetectionResult, frame: int | None = None) -> str:
    return json.dumps(result_record(source, result, frame))


def result_text(label: str, result: DetectionResult) -> str:
    """One line: ``label: WxH, N detection(s): name score [x1, y1, x2, y2], ... (timings)``."""
    found = ", ".join(
        f"{name} {score:.2f} [{', '.join(f'{v:.0f}' for v in box)}]"
        for name, score, box in zip(
            result.class_names, result.scores.tolist(), result.xyxy.tolist(), strict=True
        )
    )
    t = result.timing
    return (
        f"{label}: {result.image_width}x{result.image_height}, {len(result)} detection(s)"
        f"{': ' + found if found else ''} (pre {t.preprocess_ms:.1f} ms, "
        f"infer {t.inference_ms:.1f} ms, post {t.postprocess_ms:.1f} ms)"
    )
