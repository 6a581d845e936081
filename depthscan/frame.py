"""A depth frame as a virtual laser scan is made from it, for a robot whose obstacles are
seen by a depth camera rather than a laser: the samples the scan is made from, whether a frame
can be trusted, what a camera cannot see below it. Pure numpy: no bus, no clock.

Every ``stride_px``-th row and column of the depth image is taken (before anything is
converted: :func:`sample_frame`; a pixel there that reads nothing is filled from its row's
neighbours in the stride, :func:`_take`, so that a camera's scattered dropped pixels do not
add up to a hole); depthscan/observe.py reads them as floor, obstacles,
drop-offs and holes and makes the scan, in the ROBOT frame (REP 103: angle 0 forward,
counter-clockwise positive), 360 deg round, NaN outside the field of view. A camera whose
height above the floor is not known (``mount_height_m`` 0) cannot tell the floor from an
obstacle: it gives no virtual scan (``depth_no_mount``). A frame whose intrinsics or mounting
are implausible (:func:`implausible`) gives none either.

No separate check of the floor per frame: a height announced wrong by more than
``floor_margin_m`` puts the floor seen above the margin (an obstacle) or below it (a
drop-off), and one above ``max_height_m`` puts everything overhead (no floor: blocked), so a
wrong height blocks wherever the floor is seen, while a check that the lower rows sit on the
floor would block a normal scene whose lower rows show a box, a ramp or a person.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.messages import DepthFrame
from perception import Intrinsics, Mounting

#: The range a scan states when its depth image states none (DepthFrame.range_max_m 0).
UNSTATED_RANGE_MAX_M = 100.0
#: The nearest a camera that states no minimum range is taken to see (metres along its axis):
#: where a direction with no reading blocks. Above 0, so that it reads ahead of the base.
MIN_NEAR_M = 0.05


@dataclass(frozen=True, slots=True)
class ScanParams:
    """How a virtual scan is made (the controller's ``depth_*`` settings)."""

    floor_margin_m: float = 0.05
    max_height_m: float = 1.5
    stride_px: int = 4
    resolution_deg: float = 1.0
    hole_px: int = 12
    edge_band_px: int = 24
    unknown_span_m: float = 2.0
    unknown_step_m: float = 0.025


@dataclass(frozen=True, slots=True)
class Samples:
    """The pixels of a depth image a scan is made from: rows ``v`` and columns ``u`` (pixel
    indices), their depths ``z`` (len(v), len(u)) in metres (NaN: no reading) and where the
    camera said "too close" (``too_close``: 32FC1 ``-inf``)."""

    v: npt.NDArray[np.intp]
    u: npt.NDArray[np.intp]
    z: npt.NDArray[np.float64]
    too_close: npt.NDArray[np.bool_]


def _grid(
    width: int, height: int, stride: int
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The rows and columns taken: the middle of each stride."""
    return np.arange(stride // 2, height, stride), np.arange(stride // 2, width, stride)


Floats = npt.NDArray[np.float64]


def _take(
    metres: Callable[[npt.NDArray[np.intp]], Floats],
    width: int,
    u: npt.NDArray[np.intp],
    stride: int,
) -> Floats:
    """The samples of the columns ``u`` (``metres(columns)`` reads the sampled rows of those
    columns in metres: NaN no reading, ``-inf`` too close), each pixel that reads nothing
    replaced by a pixel of its own row at most ``stride // 4`` away that reads something
    (u+1, then u-1, ...; at stride 4 its two neighbours).

    A stereo camera drops single pixels here and there (the simulator's ``depth_dropout``:
    1 %); taken alone, three such in one column's samples looked like a hole ``hole_px`` tall
    where the floor must show, and the scan blocked at the camera's nearest range (a
    depth-only follower stood so for good). Three pixels side by side dropped at random, on
    three rows, is a chance of 1e-18 at 1 %. A pixel of the same row sees along the same
    elevation, so a floor reading there is the floor at this row's range; a real hole (a dark
    thing, an edge's band) three pixels wide or more stays a hole."""
    z = metres(u)
    missing = np.isnan(z)
    for step in range(1, stride // 4 + 1):
        for d in (step, -step):
            if not missing.any():
                return z
            alt = metres(np.clip(u + d, 0, width - 1))
            fill = missing & ~np.isnan(alt)
            z[fill] = alt[fill]
            missing &= ~fill
    return z


def sample_metres(depth: npt.NDArray[np.float32], stride: int) -> Samples:
    """The samples of an image already in metres (perception/depth.py ``depth_metres``: NaN =
    no reading; ``-inf`` kept as "too close"), a pixel that reads nothing filled from its
    row's neighbours (:func:`_take`)."""
    h, w = depth.shape
    v, u = _grid(w, h, stride)

    def metres(cols: npt.NDArray[np.intp]) -> Floats:
        z = depth[np.ix_(v, cols)].astype(np.float64)
        out: Floats = np.where(np.isfinite(z) & (z > 0) | np.isneginf(z), z, np.nan)
        return out

    z = _take(metres, w, u, stride)
    too_close = np.isneginf(z)
    return Samples(v, u, np.where(too_close, np.nan, z), too_close)


def sample_frame(frame: DepthFrame, stride: int) -> Samples:
    """The samples of a depth frame, taken from its raw image before conversion (a 640x480
    image at stride 4 converts 19,200 pixels, not 307,200). No reading: 0, NaN, +inf, or
    outside the stated range; "too close": 32FC1 ``-inf`` (REP 117; 16UC1 cannot say it)."""
    v, u = _grid(frame.width, frame.height, stride)
    if frame.encoding == "16UC1":
        raw = np.frombuffer(frame.data, "<u2").reshape(frame.height, frame.width)
        scale = 1.0 / 1000.0
    else:
        raw = np.frombuffer(frame.data, "<f4").reshape(frame.height, frame.width)
        scale = 1.0

    def metres(cols: npt.NDArray[np.intp]) -> Floats:
        z = raw[np.ix_(v, cols)].astype(np.float64) * scale
        bad = ~np.isfinite(z) | (z <= 0) | (z < frame.range_min_m)
        if frame.range_max_m > 0:
            bad |= z > frame.range_max_m
        out: Floats = np.where(bad & ~np.isneginf(z), np.nan, z)
        return out

    z = _take(metres, frame.width, u, stride)
    too_close = np.isneginf(z)
    return Samples(v, u, np.where(too_close, np.nan, z), too_close)


def usable(mount: Mounting) -> bool:
    """Whether a camera mounted so can give a virtual scan: its height must be known."""
    return mount.height_m > 0


@dataclass(frozen=True, slots=True)
class Plausible:
    """What a depth frame's intrinsics and its camera's mounting must satisfy to be trusted
    (the controller's settings): the frame's horizontal field of view within
    ``hfov_tolerance_deg`` of the announced one, fx/fy within 1/``max_pixel_aspect`` ..
    ``max_pixel_aspect``, the principal point inside the image, the camera lower than
    ``max_height_m`` (above it, nothing it sees could be an obstacle)."""

    hfov_tolerance_deg: float = 5.0
    max_pixel_aspect: float = 1.25
    max_height_m: float = 1.5


def frame_hfov_deg(intr: Intrinsics) -> float:
    """The horizontal field of view of a depth image by its intrinsics, in degrees."""
    return math.degrees(2.0 * math.atan(intr.width / (2.0 * intr.fx)))


def implausible(intr: Intrinsics, hfov_deg: float, mount: Mounting, p: Plausible) -> str:
    """Why a frame seen through ``intr`` by a camera announced with ``hfov_deg`` and mounted at
    ``mount`` cannot be trusted to show obstacles ("" when it can)."""
    values = (intr.fx, intr.fy, intr.cx, intr.cy)
    if not all(math.isfinite(x) for x in values) or intr.fx <= 0 or intr.fy <= 0:
        return f"intrinsics fx {intr.fx:g}, fy {intr.fy:g}, cx {intr.cx:g}, cy {intr.cy:g}"
    aspect = intr.fx / intr.fy
    if not 1.0 / p.max_pixel_aspect <= aspect <= p.max_pixel_aspect:
        return f"fx/fy {aspect:.3g} is not within 1/{p.max_pixel_aspect:g}..{p.max_pixel_aspect:g}"
    if not (0 <= intr.cx <= intr.width and 0 <= intr.cy <= intr.height):
        return (
            f"principal point ({intr.cx:g}, {intr.cy:g}) outside the "
            f"{intr.width}x{intr.height} image"
        )
    hfov = frame_hfov_deg(intr)
    if abs(hfov - hfov_deg) > p.hfov_tolerance_deg:
        return (
            f"the image's field of view {hfov:.1f} deg is not the announced {hfov_deg:g} deg "
            f"(within {p.hfov_tolerance_deg:g})"
        )
    if not mount.height_m < p.max_height_m:
        return (
            f"announced {mount.height_m:g} m above the floor, not below depth_max_height_m "
            f"({p.max_height_m:g})"
        )
    return ""


def blind_zone(intr: Intrinsics, mount: Mounting, distance_m: float) -> tuple[float, float]:
    """What a level camera cannot see below it: the distance (from the camera, along its axis)
    from which it sees the floor, and the height below which an obstacle ``distance_m`` ahead
    of it is unseen (0: none)."""
    down = (intr.height - intr.cy) / intr.fy  # tan of the lower half of the vertical view
    if down <= 0:
        return math.inf, mount.height_m
    return mount.height_m / down, max(0.0, mount.height_m - distance_m * down)
