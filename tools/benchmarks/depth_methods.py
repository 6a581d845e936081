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

import math

import numpy as np
import numpy.typing as npt

from perception import DepthParams, Intrinsics, iou_matrix
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
    """Each box measured as ours is, its background rejection left out (module docstring)."""
    out = unknown(len(xyxy))
    for i, box in enumerate(np.asarray(xyxy, np.float64).reshape(-1, 4)):
        row = _no_rejection_box(depth, intr, box, params)
        if row is not None:
            _set(out, i, *row)
    return out


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


def _no_rejection_box(
    depth: Depth, intr: Intrinsics, box: npt.NDArray[np.float64], p: DepthParams
) -> tuple[float, float, float] | None:
    x1, y1, x2, y2 = (float(b) for b in box)
    if not np.isfinite(box).all() or x2 <= x1 or y2 <= y1:
        return None
    h, w = depth.shape
    c0, c1 = max(0, int(np.floor(x1))), min(w, int(np.ceil(x2)))
    r0, r1 = max(0, int(np.floor(y1))), min(h, int(np.ceil(y2)))
    if c1 <= c0 or r1 <= r0:
        return None
    step = max(1, int(np.ceil(np.sqrt((c1 - c0) * (r1 - r0) / p.max_samples))))
    patch = depth[r0:r1:step, c0:c1:step]
    valid = np.isfinite(patch) & (patch > 0)
    count = int(np.count_nonzero(valid))
    if count < p.min_valid_pixels or count < p.min_valid_fraction * patch.size:
        return None
    rows, cols = np.nonzero(valid)
    z = patch[rows, cols].astype(np.float64)
    u, v = c0 + cols * step + 0.5, r0 + rows * step + 0.5
    du = (u - (x1 + x2) / 2) / max((x2 - x1) / 2, 0.5)
    dv = (v - (y1 + y2) / 2) / max((y2 - y1) / 2, 0.5)
    weight = np.exp(-0.5 * (du * du + dv * dv) / (p.centre_sigma * p.centre_sigma))
    order = np.argsort(z)
    cum = np.cumsum(weight[order])
    zc = float(z[order][np.searchsorted(cum, 0.5 * cum[-1])])
    q = (p.extent_percentile, 100.0 - p.extent_percentile)
    (xlo, ylo), (xhi, yhi) = np.percentile(
        np.stack(((u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy)), q, axis=1
    )
    return float(xlo + xhi) / 2, float(ylo + yhi) / 2, zc
