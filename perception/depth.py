"""Distance from an aligned depth image: each box's distance, 3D centre and extent. Pure numpy.

The columns a detection gets (``Boxes.columns``, docs/messages.md), in the camera's optical
frame (REP 103: x right, y down, z forward), metres, NaN where unknown. They describe the
object's VISIBLE SURFACE, what the camera sees of it (the cluster of its box's depths that is
the object), not its hidden volume:

    distance_m                 the distance from the camera to that centre, sqrt(x² + y² + z²)
    x_m, y_m, z_m              the centre of the visible surface: z the median depth of the
                               object's cluster, x and y the middle of its points
    size_x_m, size_y_m, size_z_m
                               the extent along x, y and z of the visible points (size_z_m:
                               the depth extent of the visible part, not the object's depth)

A person's distance is so to their front, as a laser's is: their middle is some 10-15 cm
farther, which no camera sees.

"Unknown" (NaN in every column of the row) when the box holds too few valid depth pixels:
never a made-up number. Depth and colour are aligned: a box in colour pixels is scaled to the
depth image's size (:func:`to_depth_pixels`).
"""

from __future__ import annotations

from dataclasses import dataclass
from statistics import NormalDist
from typing import Protocol

import numpy as np
import numpy.typing as npt

from common.messages import MAX_DEPTH_RANGE_M, DepthFrame

DISTANCE = "distance_m"
CENTRE = ("x_m", "y_m", "z_m")
SIZE = ("size_x_m", "size_y_m", "size_z_m")
#: Every column the depth stage adds, in this order.
COLUMNS: tuple[str, ...] = (DISTANCE, *CENTRE, *SIZE)

#: A reading under a millimetre (16UC1's unit) is no reading: a 32FC1 source's denormals.
MIN_READING_M = 0.001

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
    than either makes its row unknown (and so does an object cluster of fewer than
    ``min_valid_pixels``). ``max_samples``: a larger box is sampled on a regular grid of at
    most this many pixels. ``centre_sigma``: the centre weight's Gaussian width, as a fraction
    of the box's half-size (a pixel at the box's edge weighs exp(-0.5 / sigma**2)).
    ``min_bin_fraction``: the depth histogram's narrowest bin, a fraction of the depth;
    ``bin_noise_scale``: the bin width in measured noise sigmas where that is wider.
    ``gap_fraction``: a run of bins holding less than this fraction of the box's weight
    separates two clusters. ``min_cluster_fraction``: the nearest cluster with at least this
    fraction of the weight is the object. ``extent_percentile``: the extent runs from this
    percentile to its complement of the object's points. ``reject_background`` false takes
    every valid reading in the box as the object's (no clusters): only to measure what the
    rejection buys (tools/benchmarks/depth_methods.py)."""

    min_valid_pixels: int = 20
    min_valid_fraction: float = 0.05
    max_samples: int = 4096
    centre_sigma: float = 0.5
    min_bin_fraction: float = 0.01
    bin_noise_scale: float = 2.0
    gap_fraction: float = 0.005
    min_cluster_fraction: float = 0.2
    extent_percentile: float = 2.0
    reject_background: bool = True


def depth_metres(frame: DepthFrame) -> Depth:
    """The image as (h, w) float32 metres, NaN where there is no reading (0, NaN, inf, under
    a millimetre, or outside the frame's stated range; beyond ``MAX_DEPTH_RANGE_M`` where it
    states none)."""
    if frame.encoding == "16UC1":
        raw = np.frombuffer(frame.data, "<u2").reshape(frame.height, frame.width)
        z = raw.astype(np.float32) / 1000.0
    else:
        z = np.frombuffer(frame.data, "<f4").reshape(frame.height, frame.width).astype(np.float32)
    bad = ~np.isfinite(z) | (z < max(MIN_READING_M, frame.range_min_m))
    bad |= z > (frame.range_max_m if frame.range_max_m > 0 else MAX_DEPTH_RANGE_M)
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

    Per box (docs/depth.md, "The method"): the valid depths of the box (clipped to the image,
    sampled on a grid of at most ``max_samples``), each weighted by a Gaussian of its distance
    from the box's centre; a weighted histogram of log-depth whose bin width follows the noise
    measured between neighbouring pixels; its clusters (runs of bins split by near-empty
    gaps); the object is the nearest cluster holding ``min_cluster_fraction`` of the weight
    (the heaviest if none does): what is in front of the background. Its weighted median
    depth is z; x and y are the middle of its back-projected points' robust range, the extent
    that range (z's net of the noise). Too few valid pixels: the row stays unknown (NaN)."""
    out = unknown(len(xyxy))
    boxes = np.asarray(xyxy, np.float64).reshape(-1, 4)
    for i in range(len(boxes)):
        row = _measure_box(depth, intr, boxes[i], params)
        if row is not None:
            for name, value in zip(COLUMNS, row, strict=True):
                out[name][i] = value
    return out


# The z-score of a percentile, for taking the noise's share out of a robust range.
def _z_of(percentile: float) -> float:
    return float(NormalDist().inv_cdf(1.0 - percentile / 100.0))


def _measure_box(
    depth: Depth, intr: Intrinsics, box: npt.NDArray[np.float64], p: DepthParams
) -> tuple[float, ...] | None:
    x1, y1, x2, y2 = (float(b) for b in box)
    if not np.isfinite(box).all() or x2 <= x1 or y2 <= y1:
        return None  # no box, or a zero-size one
    h, w = depth.shape
    c0, c1 = max(0, int(np.floor(x1))), min(w, int(np.ceil(x2)))
    r0, r1 = max(0, int(np.floor(y1))), min(h, int(np.ceil(y2)))
    if c1 <= c0 or r1 <= r0:
        return None  # wholly outside the image
    step = max(1, int(np.ceil(np.sqrt((c1 - c0) * (r1 - r0) / p.max_samples))))
    patch = depth[r0:r1:step, c0:c1:step]
    valid = np.isfinite(patch) & (patch > 0)
    count = int(np.count_nonzero(valid))
    if count < p.min_valid_pixels or count < p.min_valid_fraction * patch.size:
        return None
    rows, cols = np.nonzero(valid)
    z = patch[rows, cols].astype(np.float64)
    u = c0 + cols * step + 0.5  # pixel centres
    v = r0 + rows * step + 0.5
    # The weight falls with the distance from the (unclipped) box's centre: the object fills
    # the middle of its box, background and neighbours its corners.
    du = (u - (x1 + x2) / 2) / max((x2 - x1) / 2, 0.5)
    dv = (v - (y1 + y2) / 2) / max((y2 - y1) / 2, 0.5)
    weight = np.exp(-0.5 * (du * du + dv * dv) / (p.centre_sigma * p.centre_sigma))
    noise = _relative_noise(np.log(np.where(valid, patch, np.float32(np.nan))))
    lz = np.log(z)
    lo, span = float(lz.min()), float(lz.max() - lz.min())
    bin_width = max(p.min_bin_fraction, p.bin_noise_scale * noise, span / 2048)
    idx = ((lz - lo) / bin_width).astype(np.int64)
    hist = np.bincount(idx, weight, int(idx.max()) + 1)
    smooth = np.convolve(hist, np.full(3, 1 / 3), mode="same")
    total = float(hist.sum())
    if p.reject_background:
        first, last = _object_bins(smooth, total, p)
        sel = (idx >= first) & (idx <= last)
    else:
        sel = np.ones(len(z), bool)
    if int(np.count_nonzero(sel)) < p.min_valid_pixels:
        return None
    zs, ws, us, vs = z[sel], weight[sel], u[sel], v[sel]
    zc = _weighted_median(zs, ws)
    xs = (us - intr.cx) * zs / intr.fx
    ys = (vs - intr.cy) * zs / intr.fy
    q = (p.extent_percentile, 100.0 - p.extent_percentile)
    (xlo, ylo, zlo), (xhi, yhi, zhi) = np.percentile(np.stack((xs, ys, zs)), q, axis=1)
    x, y = (xlo + xhi) / 2, (ylo + yhi) / 2
    # An object's pixels spread evenly over its width and height: the robust range leaves
    # out 2 * extent_percentile % of it.
    spread = 1.0 - 2.0 * p.extent_percentile / 100.0
    # The range of a flat surface's depths is the noise's: take its share out.
    noise_range = 2 * _z_of(p.extent_percentile) * noise * zc
    size_z = float(np.sqrt(max((zhi - zlo) ** 2 - noise_range**2, 0.0)))
    return (
        float(np.sqrt(x * x + y * y + zc * zc)),
        float(x),
        float(y),
        zc,
        float(xhi - xlo) / spread,
        float(yhi - ylo) / spread,
        size_z,
    )


def _relative_noise(log_patch: npt.NDArray[np.float32]) -> float:
    """The depth noise as a fraction of the depth: the robust spread of the log-depth step
    between horizontal neighbours (most neighbours lie on one surface; a step between two
    surfaces is an outlier the median ignores)."""
    d = np.abs(np.diff(log_patch, axis=1))
    d = d[np.isfinite(d)]
    if d.size == 0:
        return 0.0
    # median |a - b| of two N(0, s) draws is 0.6745 * sqrt(2) * s
    return float(np.median(d)) / (0.6745 * float(np.sqrt(2.0)))


def _object_bins(smooth: npt.NDArray[np.float64], total: float, p: DepthParams) -> tuple[int, int]:
    """The first and last bin of the object's cluster: the nearest run of occupied bins that
    holds ``min_cluster_fraction`` of the weight, else the heaviest run."""
    occupied = smooth > p.gap_fraction * total
    edges = np.diff(np.concatenate(([0], occupied.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    if starts.size == 0:  # weight spread thinner than the gap everywhere: one cluster
        return 0, len(smooth) - 1
    cumulative = np.concatenate(([0.0], np.cumsum(smooth)))
    mass = cumulative[ends + 1] - cumulative[starts]
    enough = np.flatnonzero(mass >= p.min_cluster_fraction * float(mass.sum()))
    k = int(enough[0]) if enough.size else int(np.argmax(mass))
    return int(starts[k]), int(ends[k])


def _weighted_median(values: npt.NDArray[np.float64], weights: npt.NDArray[np.float64]) -> float:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


class Mounted(Protocol):
    """What says where a camera stands: its announcement (common/messages.py
    ``CameraAnnouncement``) or its settings (the camera's ``mount_*``)."""

    @property
    def mount_x_m(self) -> float: ...

    @property
    def mount_y_m(self) -> float: ...

    @property
    def mount_height_m(self) -> float: ...

    @property
    def mount_yaw_deg(self) -> float: ...


@dataclass(frozen=True, slots=True)
class Mounting:
    """Where a camera stands on the robot (its CameraAnnouncement's ``mount_*``): ``x_m``
    forward and ``y_m`` left of the base's centre, ``height_m`` above the floor, looking
    ``yaw_deg`` counter-clockwise from forward, level. The one transform from a camera's
    frame to the robot's (:func:`to_robot`): the controller, the scan, the viewer and the
    ROS 2 bridge all place a camera with it."""

    x_m: float = 0.0
    y_m: float = 0.0
    height_m: float = 0.0
    yaw_deg: float = 0.0

    @classmethod
    def of(cls, camera: Mounted) -> Mounting:
        """Where an announced (or configured) camera stands on the robot."""
        return cls(camera.mount_x_m, camera.mount_y_m, camera.mount_height_m, camera.mount_yaw_deg)


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
