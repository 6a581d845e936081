"""Distance from an aligned depth image: each box's distance, 3D centre and extent. Pure numpy.

The columns a detection gets (``Boxes.columns``, docs/messages.md), in the camera's optical
frame (REP 103: x right, y down, z forward), metres, NaN where unknown:

    distance_m                 the distance from the camera to the object's 3D centre
    x_m, y_m, z_m              the 3D centre
    size_x_m, size_y_m, size_z_m
                               the extent along x, y and z

"Unknown" (NaN in every column of the row) when the box holds too few valid depth pixels:
never a made-up number. Depth and colour are aligned: a box in colour pixels is scaled to the
depth image's size (:func:`to_depth_pixels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import DepthFrame

DISTANCE = "distance_m"
CENTRE = ("x_m", "y_m", "z_m")
SIZE = ("size_x_m", "size_y_m", "size_z_m")
#: Every column the depth stage adds, in this order.
COLUMNS: tuple[str, ...] = (DISTANCE, *CENTRE, *SIZE)

Depth = npt.NDArray[np.float32]  # (h, w) metres, NaN where there is no reading


@dataclass(frozen=True, slots=True)
class Intrinsics:
    """A pinhole camera's intrinsics, in pixels of a ``width`` x ``height`` image."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def of(cls, frame: DepthFrame) -> Intrinsics:
        return cls(frame.fx, frame.fy, frame.cx, frame.cy, frame.width, frame.height)

    @classmethod
    def from_hfov(cls, width: int, height: int, hfov_deg: float) -> Intrinsics:
        """Square pixels, the principal point at the centre, the horizontal field of view."""
        f = (width / 2) / float(np.tan(np.radians(hfov_deg) / 2))
        return cls(f, f, width / 2, height / 2, width, height)


@dataclass(frozen=True, slots=True)
class DepthParams:
    """How a box's depth is measured (the detector's ``depth_*`` settings).

    ``min_valid_pixels``/``min_valid_fraction``: fewer valid depth pixels in the box's region
    than both makes its row unknown."""

    min_valid_pixels: int = 20
    min_valid_fraction: float = 0.05


def depth_metres(frame: DepthFrame) -> Depth:
    """The image as (h, w) float32 metres, NaN where there is no reading (0, NaN, inf, or
    outside the frame's stated range)."""
    if frame.encoding == "16UC1":
        raw = np.frombuffer(frame.data, "<u2").reshape(frame.height, frame.width)
        z = raw.astype(np.float32) / 1000.0
    else:
        z = np.frombuffer(frame.data, "<f4").reshape(frame.height, frame.width).astype(np.float32)
    bad = ~np.isfinite(z) | (z <= 0) | (z < frame.range_min_m)
    if frame.range_max_m > 0:
        bad |= z > frame.range_max_m
    return np.where(bad, np.float32(np.nan), z).astype(np.float32)


def to_depth_pixels(
    xyxy: npt.NDArray[np.float32], image_size: tuple[int, int], intr: Intrinsics
) -> npt.NDArray[np.float32]:
    """Boxes (n, 4) in pixels of an ``image_size`` (width, height) colour image, as pixels of
    the aligned depth image."""
    sx, sy = intr.width / image_size[0], intr.height / image_size[1]
    out: npt.NDArray[np.float32] = (xyxy * np.array([sx, sy, sx, sy], np.float32)).astype(
        np.float32
    )
    return out


def unknown(n: int) -> dict[str, npt.NDArray[np.float32]]:
    """The columns of ``n`` detections with no depth (every value NaN)."""
    return {name: np.full(n, np.nan, np.float32) for name in COLUMNS}


def measure(
    depth: Depth,
    intr: Intrinsics,
    xyxy: npt.NDArray[np.float32],
    params: DepthParams = DepthParams(),
) -> dict[str, npt.NDArray[np.float32]]:
    """The depth columns (:data:`COLUMNS`) of boxes ``xyxy`` (n, 4), in pixels of ``depth``.

    Baseline method: the median of the valid depths in the middle half of the box, the box's
    centre and size back-projected at that depth, the extent in z from the 10th to 90th
    percentile of the depths within 1 m of the median."""
    out = unknown(len(xyxy))
    h, w = depth.shape
    for i, (x1, y1, x2, y2) in enumerate(xyxy.astype(np.float64)):
        qx, qy = (x2 - x1) / 4, (y2 - y1) / 4
        c0, c1 = int(max(0, np.floor(x1 + qx))), int(min(w, np.ceil(x2 - qx)))
        r0, r1 = int(max(0, np.floor(y1 + qy))), int(min(h, np.ceil(y2 - qy)))
        if c1 <= c0 or r1 <= r0:
            continue
        patch = depth[r0:r1, c0:c1]
        valid = patch[np.isfinite(patch)]
        if len(valid) < params.min_valid_pixels or len(valid) < params.min_valid_fraction * (
            patch.size
        ):
            continue
        z = float(np.median(valid))
        near = valid[np.abs(valid - z) <= 1.0]
        u, v = (x1 + x2) / 2, (y1 + y2) / 2
        x, y = (u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy
        lo, hi = np.percentile(near, [10, 90])
        row = (
            float(np.sqrt(x * x + y * y + z * z)),
            x,
            y,
            z,
            (x2 - x1) * z / intr.fx,
            (y2 - y1) * z / intr.fy,
            float(hi - lo),
        )
        for name, value in zip(COLUMNS, row, strict=True):
            out[name][i] = value
    return out


@dataclass(frozen=True, slots=True)
class Mounting:
    """Where a camera stands on the robot (its CameraAnnouncement's ``mount_*``): ``x_m``
    forward and ``y_m`` left of the base's centre, ``height_m`` above the floor, looking
    ``yaw_deg`` counter-clockwise from forward, level."""

    x_m: float = 0.0
    y_m: float = 0.0
    height_m: float = 0.0
    yaw_deg: float = 0.0


def to_robot(
    x: npt.NDArray[np.float32],
    y: npt.NDArray[np.float32],
    z: npt.NDArray[np.float32],
    mount: Mounting,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Points in a camera's optical frame (x right, y down, z forward) as (forward, left, up)
    in the robot's base frame on the floor (REP 103), by the camera's mounting."""
    fwd, left, up = z.astype(np.float64), -x.astype(np.float64), -y.astype(np.float64)
    yaw = np.radians(mount.yaw_deg)
    c, s = np.cos(yaw), np.sin(yaw)
    return (
        mount.x_m + c * fwd - s * left,
        mount.y_m + s * fwd + c * left,
        mount.height_m + up,
    )
