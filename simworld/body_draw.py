"""The drawing of a body's silhouette (:func:`silhouette`, cached per pose). Pure.

Each part is a solid whose front surface is computed per pixel over its own bounding box, in
metres on the canonical canvas: the torso and the neck elliptic cylinders (their exact front
surface for the yaw), the head an ellipsoid, arms and legs tapered capsules. Where parts
overlap the nearest surface wins, as a camera sees it. The person faces the camera at yaw 0;
a point (a to the person's left, b forward) of the person's frame is
``x = a cos(yaw) + b sin(yaw)`` right of the body's axis in the image and
``dz = a sin(yaw) - b cos(yaw)`` behind it along the optical axis.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from common.images import Image
from simworld.body import (
    ARM_SWING_DEG,
    BGR,
    CACHE_SIZE,
    CANON_PX,
    LEG_SWING_DEG,
    PHASES,
    SHOES,
    Body,
    Floats,
    Silhouette,
    cloth,
    coat,
    face_texture,
    shade,
)

Profile = Callable[[Floats], Floats]  # a half-width (m) per height (m)

#: A head turned further than this from the camera shows no face (degrees).
FACE_MAX_YAW_DEG = 70.0
#: The canvas's width in metres, centred on the body's axis: enough for a stride side-on.
CANVAS_M = 1.3


@dataclass(frozen=True, slots=True)
class Grid:
    """The canonical canvas: pixel centres' x (m, right of the axis) per column and y (m up
    from the floor) per row."""

    x: Floats
    y: Floats
    ppm: float


@dataclass(slots=True)
class Canvas:
    """The nearest surface so far (``dz``, inf: nothing) and each pixel's colour."""

    dz: Floats
    colour: Image


def _grid(body: Body) -> Grid:
    ppm = CANON_PX / body.height_m
    w = round(CANVAS_M * ppm)
    x = ((np.arange(w, dtype=np.float32) + 0.5) / ppm - w / ppm / 2).astype(np.float32)
    y = (body.height_m - (np.arange(CANON_PX, dtype=np.float32) + 0.5) / ppm).astype(np.float32)
    return Grid(x, y, ppm)


def _rows(g: Grid, y0: float, y1: float) -> slice:
    """The rows whose centres lie between heights y0 < y1 (metres)."""
    a = int(np.searchsorted(-g.y, -y1))
    b = int(np.searchsorted(-g.y, -y0, side="right"))
    return slice(a, b)


def _cols(g: Grid, x0: float, x1: float) -> slice:
    a = int(np.searchsorted(g.x, x0))
    b = int(np.searchsorted(g.x, x1, side="right"))
    return slice(a, b)


def _put(
    cv: Canvas, g: Grid, rs: slice, cs: slice, dz: Floats, colour: BGR, tex: Floats | None = None
) -> None:
    """Lay a part's surface ``dz`` (inf: not on the part) over the canvas where it is nearer,
    in ``colour`` shaded by how squarely the surface faces the camera (its slopes) and by
    the cloth's folds (``tex``, the light per pixel of ``dz``'s box; None: the tiled cloth)."""
    old = cv.dz[rs, cs]
    near = dz < old
    if not near.any():
        return
    old[near] = dz[near]
    if min(dz.shape) < 2:
        cv.colour[rs, cs][near] = colour
        return
    gy, gx = np.gradient(np.where(np.isfinite(dz), dz, np.nan))
    with np.errstate(invalid="ignore"):
        nz = 1.0 / np.sqrt(1.0 + (gx * g.ppm) ** 2 + (gy * g.ppm) ** 2)
    # a rim pixel (its neighbour off the part) has no slope: as dark as a steep surface
    light = np.nan_to_num(nz, nan=0.2).astype(np.float32)
    if tex is not None:
        light *= tex
    elif colour != SHOES:
        light *= cloth(g.ppm, cv.dz.shape)[rs, cs]
    cv.colour[rs, cs][near] = shade(colour, light)[near]


def _cylinder(
    cv: Canvas, g: Grid, yaw: float, y0: float, y1: float, ra: float | Profile, rb: float,
    off: float, colour: BGR, coated: bool = False,
) -> None:  # fmt: skip
    """A vertical elliptic cylinder between heights y0 and y1, half-axes ``ra`` across the
    person (a float, or a function of height) and ``rb`` front to back, its axis ``off``
    metres ahead of the body's: its exact front surface for the yaw."""
    rs = _rows(g, y0, y1)
    y = g.y[rs][:, None]
    ra_y = np.asarray(ra(y) if callable(ra) else np.full_like(y, ra), np.float32)
    reach = float(np.max(ra_y)) + rb + abs(off)
    cs = _cols(g, -reach, reach)
    c, s = math.cos(yaw), math.sin(yaw)
    # the axis's offset: (a, b) = (0, off) -> x = off s, dz = -off c
    x = g.x[cs][None, :] - off * s
    ia, ib = 1.0 / ra_y**2, 1.0 / rb**2
    qa = s * s * ia + c * c * ib
    qb = x * c * s * (ia - ib)
    qc = x * x * (c * c * ia + s * s * ib) - 1.0
    disc = qb * qb - qa * qc
    with np.errstate(invalid="ignore"):
        dz = np.where(disc >= 0, (-qb - np.sqrt(disc)) / qa - off * c, np.inf)
    tex = coat((dz.shape[1], dz.shape[0])) if coated else None
    _put(cv, g, rs, cs, dz.astype(np.float32), colour, tex)


def _ellipsoid(
    cv: Canvas, g: Grid, centre: tuple[float, float, float], r: float, ry: float, colour: BGR
) -> None:
    """A head: horizontal sections circles of radius ``r``, ``ry`` tall each side; ``centre``
    (x, y, dz) in the canvas's frame."""
    cx, cy, cz = centre
    rs, cs = _rows(g, cy - ry, cy + ry), _cols(g, cx - r, cx + r)
    u = ((g.x[cs][None, :] - cx) / r) ** 2 + ((g.y[rs][:, None] - cy) / ry) ** 2
    with np.errstate(invalid="ignore"):
        dz = np.where(u <= 1.0, cz - r * np.sqrt(1.0 - u), np.inf).astype(np.float32)
    _put(cv, g, rs, cs, dz, colour)


def _capsule(
    cv: Canvas,
    g: Grid,
    p0: tuple[float, float, float],
    p1: tuple[float, float, float],
    r0: float,
    r1: float,
    colour: BGR,
) -> None:
    """A tapered limb from ``p0`` to ``p1`` ((x, y, dz) in the canvas's frame), radius
    ``r0`` to ``r1``: each pixel's nearest point on the axis in the image, and the round
    surface over it."""
    (x0, y0, z0), (x1, y1, z1) = p0, p1
    r = max(r0, r1)
    rs = _rows(g, min(y0, y1) - r, max(y0, y1) + r)
    cs = _cols(g, min(x0, x1) - r, max(x0, x1) + r)
    px, py = g.x[cs][None, :] - x0, g.y[rs][:, None] - y0
    dx, dy = x1 - x0, y1 - y0
    t = np.clip((px * dx + py * dy) / max(dx * dx + dy * dy, 1e-12), 0.0, 1.0)
    rho2 = (px - t * dx) ** 2 + (py - t * dy) ** 2
    rad = r0 + t * (r1 - r0)
    with np.errstate(invalid="ignore"):
        dz = np.where(rho2 <= rad * rad, z0 + t * (z1 - z0) - np.sqrt(rad * rad - rho2), np.inf)
    _put(cv, g, rs, cs, dz.astype(np.float32), colour)


@lru_cache(maxsize=CACHE_SIZE)
def silhouette(body: Body, yaw_deg: float, phase: int | None) -> Silhouette:
    """The person drawn at ``yaw_deg`` (0: facing the camera; 90: facing the image's right,
    their right side to the camera; -90: facing its left; 180: their back to it), at
    ``phase`` of :data:`PHASES` of their stride (None: standing); pass a
    :func:`~simworld.body.pose_key`."""
    return draw(body, yaw_deg, None if phase is None else phase / PHASES)


def draw(body: Body, yaw_deg: float, phase: float | None) -> Silhouette:
    """The silhouette of ``body`` at ``yaw_deg`` and ``phase`` (0..1; None: standing)."""
    g = _grid(body)
    cv = Canvas(
        np.full((g.y.size, g.x.size), np.inf, np.float32),
        np.zeros((g.y.size, g.x.size, 3), np.uint8),
    )
    yaw = math.radians(yaw_deg)
    c, s = math.cos(yaw), math.sin(yaw)

    def at(a: float, b: float, y: float) -> tuple[float, float, float]:
        return a * c + b * s, y, a * s - b * c

    h = body.height_m
    swing = 0.0 if phase is None else math.sin(2 * math.pi * phase)
    leg_len = 0.48 * h
    leg = math.radians(LEG_SWING_DEG) * swing
    hip_y = leg_len * math.cos(leg)  # the hips drop as the legs open: both feet on the floor
    hip_a = 0.2 * body.shoulder_m
    half_d = body.depth_m / 2
    for side in (1.0, -1.0):
        ang = side * leg
        foot = (side * (hip_a + 0.03), leg_len * math.sin(ang), hip_y - leg_len * math.cos(ang))
        _capsule(cv, g, at(side * hip_a, 0.0, hip_y + 0.05), at(*foot), 0.09 * h / 1.75,
                 0.055 * h / 1.75, body.trousers)  # fmt: skip
        toe = (foot[0], foot[1] + 0.13, 0.035)
        _capsule(cv, g, at(foot[0], foot[1] - 0.03, 0.04), at(*toe), 0.045, 0.035, SHOES)
    shoulder_y = hip_y + 0.33 * h
    top_y = shoulder_y + 0.025 * h
    sh, waist, hips = body.shoulder_m / 2, 0.36 * body.shoulder_m, 0.4 * body.shoulder_m

    def half_width(y: Floats) -> Floats:
        up = np.clip((y - hip_y) / (shoulder_y - hip_y), 0.0, 1.0)
        w = np.where(up < 0.4, hips + (waist - hips) * up / 0.4,
                     waist + (sh - waist) * (up - 0.4) / 0.6)  # fmt: skip
        over = np.clip((y - shoulder_y) / (top_y - shoulder_y), 0.0, 1.0)
        out: Floats = (
            w * np.sqrt(np.clip(1.0 - 0.75 * over**2, 0.0, 1.0)) * 0.85 + 0.15 * w * (1.0 - over)
        ).astype(np.float32)
        return out

    _cylinder(cv, g, yaw, hip_y - 0.04 * h, top_y, half_width, half_d, 0.0, body.top,
              coated=abs(yaw_deg) <= FACE_MAX_YAW_DEG + 30)  # fmt: skip
    arm_len = 0.36 * h
    arm = -math.radians(ARM_SWING_DEG) * swing
    for side in (1.0, -1.0):
        ang = -side * arm
        a0 = side * (sh - 0.035)
        hand = (side * (sh + 0.02), arm_len * math.sin(ang), shoulder_y - arm_len * math.cos(ang))
        _capsule(cv, g, at(a0, 0.0, shoulder_y), at(*hand), 0.06, 0.042, body.top)
        _capsule(cv, g, at(*hand), at(hand[0], hand[1] + 0.02 * math.sin(ang), hand[2] - 0.09),
                 0.04, 0.035, body.skin)  # fmt: skip
    head_ry = 0.068 * h
    head_y = h - head_ry
    _cylinder(cv, g, yaw, top_y - 0.03, head_y - 0.5 * head_ry, 0.055, 0.055, 0.01, body.skin)
    _head(cv, g, body, at(0.0, 0.02, head_y), head_ry, yaw_deg)
    return _finish(cv, g, body)


def _head(
    cv: Canvas, g: Grid, body: Body, centre: tuple[float, float, float], ry: float, yaw_deg: float
) -> None:
    """The head: skin where it faces the camera, hair on its top and back."""
    r = 0.085 * body.height_m / 1.75
    before = cv.dz.copy()
    _ellipsoid(cv, g, centre, r, ry, body.skin)
    cx, cy, _ = centre
    hair_from = cy + (0.25 if abs(yaw_deg) <= 100 else -1.0) * ry
    on = (cv.dz < before) & (g.y[:, None] > hair_from)
    if abs(yaw_deg) > 45 and abs(yaw_deg) <= 100:  # side-on: the back half is hair
        back = np.sign(yaw_deg) * (g.x[None, :] - cx) < 0
        on |= (cv.dz < before) & back & (g.y[:, None] > cy - 0.4 * ry)
    cv.colour[on] = body.hair
    if abs(yaw_deg) <= FACE_MAX_YAW_DEG:
        _face_on(cv, g, body, (cx - r * math.sin(math.radians(yaw_deg)) * 0.5, cy), r, ry, before)


def _face_on(
    cv: Canvas, g: Grid, body: Body, centre: tuple[float, float], r: float, ry: float,
    before: Floats,
) -> None:  # fmt: skip
    """A real face (a photo's, tinted to the body's skin) over the head's pixels, centred at
    ``centre`` (x, y in metres) where the head turns its face."""
    cx, cy = centre
    rs, cs = _rows(g, cy - ry * 1.05, cy + ry * 1.1), _cols(g, cx - r * 1.1, cx + r * 1.1)
    h, w = rs.stop - rs.start, cs.stop - cs.start
    if h < 2 or w < 2:
        return
    tex = face_texture((w, h), body.skin)
    on = cv.dz[rs, cs] < before[rs, cs]
    cv.colour[rs, cs][on] = tex[on]


def _finish(cv: Canvas, g: Grid, body: Body) -> Silhouette:
    """Crop the canvas to the person's columns and freeze it."""
    on = np.isfinite(cv.dz)
    cols = np.nonzero(on.any(axis=0))[0]
    c0, c1 = int(cols[0]), int(cols[-1]) + 1
    alpha = np.ascontiguousarray(np.where(on[:, c0:c1], 255, 0).astype(np.uint8))
    dz = np.ascontiguousarray(np.where(on[:, c0:c1], cv.dz[:, c0:c1], 0.0).astype(np.float32))
    colour = np.ascontiguousarray(cv.colour[:, c0:c1])
    axis = g.x.size / 2 - c0
    row = min(int(body.height_m / 2 * g.ppm), g.y.size - 1)  # the row at half height
    col = min(max(int(axis), 0), c1 - c0 - 1)
    truth = float(dz[row, col]) if alpha[row, col] else 0.0
    for a in (alpha, dz, colour):
        a.setflags(write=False)
    return Silhouette(alpha, colour, dz, g.ppm, axis, truth, int(np.count_nonzero(alpha)))
