"""Depth images of simple scenes for the controller's tests: the floor seen by a level camera
at a known height, and upright boxes standing on it (or hanging above it), each drawn as a
flat face square to the camera's optical axis. Metres, NaN where nothing is seen, as
perception/depth.py ``depth_metres`` gives them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.messages import DepthFrame, Header
from perception.depth import Depth, Intrinsics

W, H, HFOV = 640, 480, 60.0
INTR = Intrinsics.from_hfov(W, H, HFOV)


@dataclass(frozen=True, slots=True)
class Face:
    """A flat face ``z_m`` ahead of the camera (along its optical axis), from ``left_m`` to
    ``right_m`` across (optical x: right positive) and from ``bottom_m`` to ``top_m`` above
    the floor."""

    z_m: float
    left_m: float
    right_m: float
    bottom_m: float = 0.0
    top_m: float = 2.0


def at_bearing(z_m: float, bearing_deg: float, half_width_m: float = 0.2) -> Face:
    """A face ``z_m`` ahead whose centre is ``bearing_deg`` left of the optical axis."""
    x = -z_m * math.tan(math.radians(bearing_deg))  # optical x is to the right
    return Face(z_m, x - half_width_m, x + half_width_m)


def scene(height_m: float, *faces: Face, intr: Intrinsics = INTR) -> Depth:
    """What a level camera ``height_m`` above the floor sees: the floor below the horizon,
    nothing above it (out of range), and ``faces`` in front of both."""
    u = np.arange(intr.width) + 0.5
    v = np.arange(intr.height) + 0.5
    rx = ((u - intr.cx) / intr.fx)[None, :]  # x / z of each pixel's ray
    ry = ((v - intr.cy) / intr.fy)[:, None]  # y / z (down)
    with np.errstate(divide="ignore"):
        floor = np.where(ry > 0, height_m / np.where(ry > 0, ry, 1.0), np.inf)
    z = np.broadcast_to(floor, (intr.height, intr.width)).copy()
    for f in faces:
        x, up = rx * f.z_m, height_m - ry * f.z_m
        hit = (x >= f.left_m) & (x <= f.right_m) & (up >= f.bottom_m) & (up <= f.top_m)
        z = np.where(hit & (f.z_m < z), f.z_m, z)
    return np.where(np.isfinite(z), z, np.nan).astype(np.float32)


def depth_frame(depth: Depth, header: Header, intr: Intrinsics = INTR) -> DepthFrame:
    """``depth`` as the 16UC1 image a camera sends (mm; 0 = no reading)."""
    mm = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0).astype("<u2")
    return DepthFrame(
        header=header, encoding="16UC1", width=intr.width, height=intr.height,
        data=mm.tobytes(), fx=intr.fx, fy=intr.fy, cx=intr.cx, cy=intr.cy,
        range_min_m=0.2, range_max_m=10.0,
    )  # fmt: skip
