"""What a camera sees of the world's walls: per pixel, the nearest wall's depth and colour. Pure.

A wall (simworld/world.py :class:`~simworld.world.Wall`) is a vertical quad standing on the
floor. Column ``u`` of a pinhole camera looks along the horizontal ray ``forward + k_u * left``
(``k_u = (cx - u - 0.5) / f``, as simworld/floor.py), which meets the wall's line where

    s = (k zA - latA) / ((latB - latA) - k (zB - zA)),   z = zA + s (zB - zA)

(the wall's ends at (zA, latA) and (zB, latB) in the camera's frame: forward, left; a hit needs
0 <= s <= 1 and z in front of the camera). Every pixel of that column whose ray meets that
vertical line between the floor and the wall's top, rows with ``v + 0.5`` between
``cy - (height - h) f / z`` and ``cy + h f / z``, sees the wall at depth (along the optical
axis) ``z``: the depth is exact per pixel, constant down a column, and varies along the wall as
its perspective does. The bottom edge is where the floor at that depth is seen, so a wall stands
exactly on the floor the depth image draws.

:func:`wall_view` is the nearest wall of each pixel (the opaque walls: solid and dark), and the
nearest glass wall apart: glass hides nothing from the colour image (it is tinted over what is
behind) and reads nothing in the depth image. The colour image, the depth image and which target
shows where (simworld/render.py, depth.py) draw every other thing only where it is nearer than
the opaque wall in that pixel (:func:`in_front`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image
from simworld.floor import Pinhole, floor_rays
from simworld.world import Material, Wall, World

Floats = npt.NDArray[np.float32]

#: A solid wall's colour (BGR): a pale painted wall, apart from the background's and the
#: obstacles' greys. Shaded by how squarely the camera sees it (:data:`WALL_SHADE_MIN`).
WALL_BGR = (168, 182, 196)
#: A dark wall's colour: below sim.depth_dark_level (30), as the dark obstacles are.
DARK_WALL_BGR = (16, 15, 14)
#: A wall seen edge-on is drawn this bright (of its colour), one seen square-on fully bright:
#: the two walls of a corner differ, so a room's shape shows.
WALL_SHADE_MIN = 0.6
#: A glass wall or obstacle: this much of a pale blue-green tint over what is behind it, so a
#: person sees a pane is there and the detector still sees through it.
GLASS_BGR = (200, 215, 190)
GLASS_ALPHA = 0.12
#: Nothing of a wall nearer the camera than this (along its axis) is drawn.
NEAREST_WALL_M = 0.05


@dataclass(frozen=True, slots=True)
class WallView:
    """A camera's view of the walls: ``z`` (h, w) the depth of the nearest opaque wall in each
    pixel (inf: none), ``index`` (h, w) that wall's index in ``world.walls`` (-1: none),
    ``colour`` (h, w, 3) its colour there (meaningful where ``index`` >= 0), and ``glass_z``
    (h, w) the nearest glass wall's depth (inf: none); ``glass``: some pixel sees glass."""

    z: Floats
    index: npt.NDArray[np.int32]
    colour: Image
    glass_z: Floats

    glass: bool

    @property
    def opaque(self) -> npt.NDArray[np.bool_]:
        return self.index >= 0

    def dark(self, world: World) -> npt.NDArray[np.bool_]:
        """The pixels that show a dark wall."""
        dark = [i for i, w in enumerate(world.walls) if w.material == Material.DARK]
        return np.isin(self.index, dark) if dark else np.zeros(self.index.shape, bool)


def _columns(wall: Wall, world: World, spec: Pinhole) -> tuple[Floats, Floats] | None:
    """Per image column, the depth at which its ray meets ``wall`` (inf: it does not) and
    the cosine of the angle between the ray and the wall's normal (for its shade); None when
    no column sees it."""
    r = world.robot
    heading = r.theta + math.radians(spec.mount_yaw_deg)
    c, s = math.cos(heading), math.sin(heading)
    za, la = _to_camera(wall.x0 - r.x, wall.y0 - r.y, c, s)
    zb, lb = _to_camera(wall.x1 - r.x, wall.y1 - r.y, c, s)
    if max(za, zb) < NEAREST_WALL_M:
        return None
    f, cx = spec.focal_px, spec.width / 2
    k = (cx - np.arange(spec.width, dtype=np.float64) - 0.5) / f
    dz, dl = zb - za, lb - la
    denom = dl - k * dz
    ok = np.abs(denom) > 1e-12
    t = (k * za - la) / np.where(ok, denom, 1.0)
    z = za + t * dz
    hit = ok & (t >= 0) & (t <= 1) & (z >= NEAREST_WALL_M)
    if not hit.any():
        return None
    length = math.hypot(dz, dl)
    # |ray x wall direction| / |ray|: the cosine of the ray's angle to the wall's normal.
    cos = np.abs(dl - k * dz) / (length * np.sqrt(1 + k * k))
    return np.where(hit, z, np.inf).astype(np.float32), cos.astype(np.float32)


def _to_camera(dx: float, dy: float, c: float, s: float) -> tuple[float, float]:
    return dx * c + dy * s, -dx * s + dy * c


def _wall_block(
    wall: Wall, z: Floats, spec: Pinhole
) -> tuple[tuple[slice, slice], npt.NDArray[np.bool_]]:
    """The block of the image (rows, columns) that ``wall`` (its columns' depths ``z``) may
    cover, and which of its pixels it covers: those whose rays meet it."""
    f, cy, h = spec.focal_px, spec.height / 2, spec.height_m
    cols = np.flatnonzero(np.isfinite(z))
    u0, u1 = int(cols[0]), int(cols[-1]) + 1
    zz = z[u0:u1]
    finite = np.isfinite(zz)
    zz = np.where(finite, zz, np.float32(1.0))
    top = cy - (wall.height_m - h) * f / zz
    bottom = cy + h * f / zz
    v0 = max(math.floor(float(top[finite].min()) - 0.5), 0)
    v1 = min(math.ceil(float(bottom[finite].max())), spec.height)
    v = np.arange(v0, v1, dtype=np.float32)[:, None] + 0.5
    on: npt.NDArray[np.bool_] = (v >= top[None, :]) & (v <= bottom[None, :]) & finite[None, :]
    return (slice(v0, v1), slice(u0, u1)), on


@cache
def floor_z(spec: Pinhole) -> Floats:
    """The flat floor's depth per pixel (h, w) below the horizon, inf above it (read-only)."""
    first, z, _ = floor_rays(spec)
    out = np.full((spec.height, spec.width), np.inf, np.float32)
    out[first:] = z[:, None]
    out.setflags(write=False)
    return out


_CACHE: dict[object, WallView] = {}


def wall_view(world: World, spec: Pinhole) -> WallView | None:
    """The walls as ``spec``'s camera on the robot sees them (None: the world has none, or
    none is in view). Read-only arrays, kept for the last pose asked (the colour image, the
    depth image and the mirror's reading of one frame share one)."""
    if not world.walls:
        return None
    r = world.robot
    key = (spec, r.x, r.y, r.theta, tuple(world.walls))
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = _build(world, spec)
    view = _CACHE[key]
    return None if not view.glass and not view.opaque.any() else view


def _build(world: World, spec: Pinhole) -> WallView:
    shape = (spec.height, spec.width)
    z = np.full(shape, np.inf, np.float32)
    glass_z = np.full(shape, np.inf, np.float32)
    index = np.full(shape, -1, np.int32)
    colour = np.zeros((*shape, 3), np.uint8)
    for i, wall in enumerate(world.walls):
        cols = _columns(wall, world, spec)
        if cols is None:
            continue
        zc, cos = cols
        block, on = _wall_block(wall, zc, spec)
        depth = np.broadcast_to(zc[None, block[1]], on.shape)
        if wall.material == Material.GLASS:
            np.copyto(glass_z[block], depth, where=on & (depth < glass_z[block]))
            continue
        nearer = on & (depth < z[block])
        np.copyto(z[block], depth, where=nearer)
        np.copyto(index[block], np.int32(i), where=nearer)
        base = DARK_WALL_BGR if wall.material == Material.DARK else WALL_BGR
        shade = WALL_SHADE_MIN + (1 - WALL_SHADE_MIN) * cos[block[1]]
        col = (shade[:, None] * np.array(base, np.float32)[None, :]).astype(np.uint8)
        rows = np.ascontiguousarray(np.broadcast_to(col[None, :, :], (*on.shape, 3)))
        cv2.copyTo(rows, nearer.view(np.uint8), colour[block])
    for a in (z, glass_z, index, colour):
        a.setflags(write=False)
    return WallView(z, index, colour, glass_z, bool(np.isfinite(glass_z).any()))


def in_front(
    view: WallView | None, rect: tuple[int, int, int, int], z: float | Floats
) -> npt.NDArray[np.bool_] | None:
    """Which pixels of ``rect`` (x0, y0, x1, y1) a thing at depth ``z`` (one, or per pixel of
    the rect) shows in, nearer than the opaque walls there; None: all of them (no walls)."""
    if view is None:
        return None
    x0, y0, x1, y1 = rect
    out: npt.NDArray[np.bool_] = np.asarray(z, np.float32) < view.z[y0:y1, x0:x1]
    return out


def tint_glass(canvas: Image, view: WallView, scene_z: Floats) -> None:
    """Tint ``canvas`` where a glass wall is nearer than what the pixel shows (``scene_z``,
    its depth per pixel, inf or NaN: nothing), in place."""
    if not view.glass:
        return
    on = view.glass_z < np.nan_to_num(scene_z, nan=np.inf)
    if not on.any():
        return
    patch = canvas[on].astype(np.float32)
    tint = np.array(GLASS_BGR, np.float32)
    canvas[on] = (patch + GLASS_ALPHA * (tint - patch)).astype(np.uint8)
