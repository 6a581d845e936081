"""A person with a body in a camera's image: their pose, and their silhouette at its size. Pure.

:func:`body_silhouette` finds how a target with a :class:`~simworld.body.Body` stands to a
camera (the yaw they show it, the phase of their walk) and gives the cached silhouette of
that pose (simworld/body_draw.py); :func:`stamp` scales it to the pixels the renderer draws,
as simworld/render.py :func:`~simworld.render.layout` placed them: the colour image, the depth
image and the truth all take the person's pixels from it, so they agree pixel for pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from common.images import Image
from simworld.body import WALKING_MPS, Floats, Silhouette, pose_key, walked_m
from simworld.body_draw import silhouette
from simworld.world import Target, World

#: The time step over which a target's velocity is taken (s).
VELOCITY_DT_S = 0.05
#: How many scaled stamps are kept: a frame's people in each camera, and the next frame's.
STAMP_CACHE = 32


def walking(tg: Target, t: float) -> tuple[float, float] | None:
    """A target's velocity (m/s, world frame) while it walks faster than
    :data:`~simworld.body.WALKING_MPS`; None while it stands."""
    x0, y0 = tg.position(t - VELOCITY_DT_S)
    x1, y1 = tg.position(t + VELOCITY_DT_S)
    vx, vy = (x1 - x0) / (2 * VELOCITY_DT_S), (y1 - y0) / (2 * VELOCITY_DT_S)
    return (vx, vy) if math.hypot(vx, vy) > WALKING_MPS else None


def facing(tg: Target, t: float, robot_xy: tuple[float, float]) -> float:
    """The world yaw (radians) a target with a body faces at ``t``: its ``facing_deg``, else
    where it walks, else (standing) the robot at ``robot_xy``."""
    body = tg.body
    assert body is not None
    if body.facing_deg is not None:
        return math.radians(body.facing_deg)
    v = walking(tg, t)
    if v is not None:
        return math.atan2(v[1], v[0])
    tx, ty = tg.position(t)
    return math.atan2(robot_xy[1] - ty, robot_xy[0] - tx)


#: The torso's half-width at the hips, a share of the shoulders' width (simworld/body_draw.py
#: draws the hips 0.4 x the shoulders wide each side of the axis).
HIPS_HALF_SHARE = 0.4


def surface_m(tg: Target, t: float, robot_xy: tuple[float, float]) -> float:
    """How far the target's surface is from its centre on the line towards ``robot_xy``:
    a flat target's or an obstacle-like one's ``radius``; a body's torso at half its height,
    an ellipse ``HIPS_HALF_SHARE`` x its shoulders wide each side and half its ``depth_m``
    deep, turned by where it faces (front-on: half its depth; side-on: half its hips). What a
    depth camera reads, and a tape measure would, from the robot to the person."""
    if tg.body is None:
        return tg.radius
    tx, ty = tg.position(t)
    rel = math.atan2(robot_xy[1] - ty, robot_xy[0] - tx) - facing(tg, t, robot_xy)
    across, deep = HIPS_HALF_SHARE * tg.body.shoulder_m, tg.body.depth_m / 2
    return 1.0 / math.hypot(math.sin(rel) / across, math.cos(rel) / deep)


def body_silhouette(world: World, i: int, heading: float) -> Silhouette:
    """Target ``i``'s silhouette (it has a body) seen by a camera looking along ``heading``
    (radians, world frame) from the robot: the yaw its facing makes with the camera and the
    phase of its walk. A body with no ``facing_deg`` faces where it walks, and the robot when
    it stands (:func:`facing`)."""
    tg = world.targets[i]
    body = tg.body
    assert body is not None
    v = walking(tg, world.t)
    facing_yaw = facing(tg, world.t, (world.robot.x, world.robot.y))
    # yaw 0 faces the camera: the person faces the camera's heading turned round
    yaw = math.degrees(facing_yaw - heading) + 180.0
    phase = None if v is None else walked_m(tg.path, tg.loop, world.t) / body.stride_m % 1.0
    yaw_key, phase_key = pose_key(yaw, phase)
    return silhouette(body, yaw_key, phase_key)


@dataclass(frozen=True, slots=True)
class Stamp:
    """A silhouette scaled to its drawn pixels (``rect``'s shape): ``alpha`` (255 on the
    person), ``colour`` BGR, ``dz`` depth offsets (metres). Read-only."""

    alpha: Image
    colour: Image
    dz: Floats


def stamp(
    sil: Silhouette, full: tuple[int, int, int, int], rect: tuple[int, int, int, int] | None
) -> Stamp:
    """``sil`` scaled to fill ``full`` (x0, y0, x1, y1, end-exclusive), only the pixels of
    ``rect`` (the part of it in the image) computed."""
    assert rect is not None
    return _stamp(sil, full, rect)


@lru_cache(maxsize=STAMP_CACHE)
def _stamp(
    sil: Silhouette, full: tuple[int, int, int, int], rect: tuple[int, int, int, int]
) -> Stamp:
    x0, y0, x1, y1 = full
    cx0, cy0, cx1, cy1 = rect
    h, w = sil.alpha.shape
    sx, sy = (x1 - x0) / w, (y1 - y0) / h
    # Each output pixel's centre mapped back to the canonical silhouette (WARP_INVERSE_MAP).
    m = np.array(
        [
            [1 / sx, 0.0, (cx0 - x0 + 0.5) / sx - 0.5],
            [0.0, 1 / sy, (cy0 - y0 + 0.5) / sy - 0.5],
        ]
    )
    size = (cx1 - cx0, cy1 - cy0)
    inv = cv2.WARP_INVERSE_MAP

    def warp(a: np.ndarray, how: int) -> np.ndarray:
        out = cv2.warpAffine(a, m, size, flags=how | inv, borderMode=cv2.BORDER_CONSTANT)
        out.setflags(write=False)
        return out

    return Stamp(
        warp(sil.alpha, cv2.INTER_NEAREST),
        warp(sil.colour, cv2.INTER_LINEAR),
        warp(sil.dz, cv2.INTER_NEAREST),
    )


def drawn_area(sil: Silhouette, full: tuple[int, int, int, int]) -> float:
    """How many pixels the whole person covers at ``full``'s size (in the image or not)."""
    x0, y0, x1, y1 = full
    h, w = sil.alpha.shape
    return float(sil.area * (x1 - x0) / w * (y1 - y0) / h)
