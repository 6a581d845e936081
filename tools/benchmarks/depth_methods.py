"""The depth benchmark's naive methods and its matching of detections to targets.

Two naive depth methods, measured beside ours (perception ``measure_depth``) and the
yolo_ros-like reference (depth_reference.py) to show what ours' steps buy:

- :func:`centre_pixel`: the reading at the box's centre pixel and nothing else (unknown where
  that pixel reads nothing). A person's box centre is at half their height: their hips, or
  the floor between their legs.
- :func:`no_rejection`: ours without its background rejection: the same valid pixels, the same
  grid and centre weighting (``DepthParams``' ``max_samples``, ``centre_sigma``), the same
  minimum counts, but no clusters: z is the weighted median of every valid reading in the
  box, background and all; x and y the middle of all the points' robust range, as ours takes
  them from its cluster's.

And an oracle, to tell the body's shape from the camera's faults and the method's: :func:`surface`,
ours' statistic (the centre-weighted median) over the target's own pixels in the box, read
from the true depth image (no faults): what ours would say with a perfect camera and a perfect
cut-out of the person.

All return the depth columns (``distance_m``, ``x_m``, ``y_m``, ``z_m``; sizes NaN), NaN
where unknown, as ``measure_depth`` does.

:func:`match` pairs detections with targets by the IoU of the detection's box with the
target's true visible box (the bounding box of the pixels it owns in the image), not by the
pixel at the box's centre (with bodies that pixel often shows the floor between the legs).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

from perception import DepthParams, Intrinsics, iou_matrix
from perception import measure_depth as measure
from perception import unknown_depth as unknown

Depth = npt.NDArray[np.float32]  # (h, w) metres, NaN where there is no reading
Columns = dict[str, npt.NDArray[np.float32]]

#: The least IoU of a detection's box with a target's true visible box that pairs them. It
#: pairs, it does not grade the detector: a person filling the image is often boxed by their
#: upper or lower half only (IoU about 0.5 with their whole visible box), still their box.
MATCH_IOU = 0.3
#: Ours' default parameters: the no-rejection method's grid, weights and minimum counts.
OURS = DepthParams()


def match(
    detections: npt.NDArray[np.floating], targets: npt.NDArray[np.floating], min_iou: float
) -> dict[int, int]:
    """Target index -> detection index: pairs of boxes (xyxy) taken in descending IoU, each
    detection and each target at most once, none under ``min_iou``."""
    if len(detections) == 0 or len(targets) == 0:
        return {}
    iou = iou_matrix(np.asarray(targets).reshape(-1, 4), np.asarray(detections).reshape(-1, 4))
    out: dict[int, int] = {}
    used: set[int] = set()
    for flat in np.argsort(-iou, axis=None, kind="stable"):
        t, d = divmod(int(flat), iou.shape[1])
        if iou[t, d] < min_iou:
            break
        if t not in out and d not in used:
            out[t] = d
            used.add(d)
    return out


def horizontal(measured: Columns, i: int) -> float:
    """Row ``i``'s horizontal range hypot(x, z) in the optical frame (y is down), NaN where
    unknown: the distance the controller follows by, with the camera at the base's centre."""
    return math.hypot(float(measured["x_m"][i]), float(measured["z_m"][i]))


def _set(out: Columns, i: int, x: float, y: float, z: float) -> None:
    out["x_m"][i], out["y_m"][i], out["z_m"][i] = x, y, z
    out["distance_m"][i] = math.sqrt(x * x + y * y + z * z)


def centre_pixel(depth: Depth, intr: Intrinsics, xyxy: npt.NDArray[np.float32]) -> Columns:
    """Each box's reading at its centre pixel, back-projected through that pixel's centre."""
    out = unknown(len(xyxy))
    h, w = depth.shape
    for i, (x1, y1, x2, y2) in enumerate(np.asarray(xyxy, np.float64).reshape(-1, 4)):
        if not np.isfinite([x1, y1, x2, y2]).all():
            continue
        u = min(max(int((x1 + x2) / 2), 0), w - 1)
        v = min(max(int((y1 + y2) / 2), 0), h - 1)
        z = float(depth[v, u])
        if math.isfinite(z) and z > 0:
            _set(out, i, (u + 0.5 - intr.cx) * z / intr.fx, (v + 0.5 - intr.cy) * z / intr.fy, z)
    return out


def no_rejection(
    depth: Depth,
    intr: Intrinsics,
    xyxy: npt.NDArray[np.float32],
    params: DepthParams = OURS,
) -> Columns:
    """Each box measured as ours is, its background rejection left out (module docstring):
    ours with ``DepthParams.reject_background`` off."""
    return measure(depth, intr, xyxy, dataclasses.replace(params, reject_background=False))


def surface(
    truth: Depth,
    owner: npt.NDArray[np.int32],
    index: int,
    intr: Intrinsics,
    box: npt.NDArray[np.float32],
    params: DepthParams = OURS,
) -> tuple[float, float]:
    """The oracle (module docstring) for one box: (x, z) of the centre-weighted medians of
    the pixels of ``box`` that ``owner`` gives to ``index``, from ``truth``; NaN if none."""
    masked = np.where(owner == index, truth, np.float32(np.nan)).astype(np.float32)
    out = no_rejection(masked, intr, np.asarray(box, np.float32).reshape(1, 4), params)
    return float(out["x_m"][0]), float(out["z_m"][0])
