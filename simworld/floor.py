"""Where a camera's floor pixels land in the world, and which of them look down a drop-off. Pure.

A pixel below the horizon sees the (upper) floor at ``z = f * h / (v + 0.5 - cy)`` ahead of a
camera ``h`` above it, and ``lateral = (cx - u - 0.5) * z / f`` to its left: the same pinhole
the colour and depth images are drawn with (simworld/render.py, depth.py). Turned by the
camera's heading in the world (the robot's theta plus the camera's mounting yaw) and moved to
the robot's position, that is the pixel's ground point in the world frame.

Where that ground point lies inside a :class:`~simworld.world.Drop` the ray goes on down to
the lower floor, ``depth_m`` further: by similar triangles it meets it at
``z' = z * (h + depth_m) / h``. The approximation: the drop's walls are ignored. A ray that
would hit the far wall of a pit (or pass under the near edge of the rectangle on the lower
floor) still reads the lower floor, and the lower floor's point may lie outside the rectangle;
for a kerb or a step seen from a few metres, what matters is that the floor beyond the edge
reads farther than a flat floor would, which this gives.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from functools import cache
from typing import Protocol

import numpy as np
import numpy.typing as npt

from simworld.world import World

Floats = npt.NDArray[np.float32]


class Pinhole(Hashable, Protocol):
    """What this module needs of a camera: simworld/render.py's ``CameraSpec`` (named by
    shape, not imported: render.py draws the floor with this module). Hashable: rays are
    cached per camera."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def height_m(self) -> float: ...
    @property
    def mount_yaw_deg(self) -> float: ...
    @property
    def focal_px(self) -> float: ...


@cache
def floor_rays(spec: Pinhole) -> tuple[int, Floats, Floats]:
    """The first row below the horizon, each such row's floor z (rows,), and each column's
    lateral offset per metre of z, ``(cx - u - 0.5) / f`` (width,). Read-only."""
    f, cx, cy = spec.focal_px, spec.width / 2, spec.height / 2
    first = math.floor(cy - 0.5) + 1  # the first row whose centre is below the horizon
    below = np.arange(first, spec.height, dtype=np.float64) + 0.5 - cy
    z = (f * spec.height_m / below).astype(np.float32)
    k = ((cx - np.arange(spec.width, dtype=np.float64) - 0.5) / f).astype(np.float32)
    z.setflags(write=False)
    k.setflags(write=False)
    return first, z, k


def drop_scale(world: World, spec: Pinhole) -> Floats | None:
    """Per pixel (``spec.height``, ``spec.width``), what a floor reading is multiplied by:
    ``(h + depth_m) / h`` where the pixel looks into a drop (the deepest, where drops
    overlap), 1 elsewhere (the upper floor, and every pixel above the horizon). None when no
    drop-off is in the world (the flat floor, cached elsewhere, is then the answer)."""
    if not world.drops:
        return None
    first, z, k = floor_rays(spec)
    r = world.robot
    heading = r.theta + math.radians(spec.mount_yaw_deg)
    c, s = math.cos(heading), math.sin(heading)
    # The ground point of pixel (v, u): robot + z * (forward + k * left), world frame.
    wx = np.float32(r.x) + z[:, None] * (np.float32(c) - k * np.float32(s))[None, :]
    wy = np.float32(r.y) + z[:, None] * (np.float32(s) + k * np.float32(c))[None, :]
    deepest = np.zeros(wx.shape, np.float32)
    for d in world.drops:
        inside = (wx >= d.x0) & (wx <= d.x1) & (wy >= d.y0) & (wy <= d.y1)
        np.maximum(deepest, np.where(inside, np.float32(d.depth_m), np.float32(0)), out=deepest)
    out = np.ones((spec.height, spec.width), np.float32)
    out[first:] = (spec.height_m + deepest) / spec.height_m
    return out
