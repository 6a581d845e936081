"""Detections for the metrics tests, unit and integration alike: ``n`` boxes of a person."""

from __future__ import annotations

import numpy as np

from common.boxes import Boxes
from common.messages import Detections, Header

MS = 1_000_000


def detections(
    header: Header, n: int, *, size: tuple[int, int] = (640, 480), published_ms: float = 90.0
) -> Detections:
    """``n`` 10 px boxes, received 5 ms and published ``published_ms`` after the header's stamp."""
    stamp = header.stamp_ns
    return Detections(
        header=header,
        image_width=size[0],
        image_height=size[1],
        boxes=Boxes(
            xyxy=np.tile(np.array([0, 0, 10, 10], np.float32), (n, 1)),
            scores=np.ones(n, np.float32),
            class_ids=np.zeros(n, np.int32),
        ),
        class_names=("person",) * n,
        timing_ms={"preprocess": 2.0, "inference": 80.0, "postprocess": 1.0},
        received_ns=stamp + 5 * MS,
        published_ns=stamp + int(published_ms * MS),
    )
