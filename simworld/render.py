"""A pinhole camera that renders the world from the robot: people and photo cut-outs on a floor.

A person with a body (world.Target's ``body``) is drawn as their silhouette (simworld/body.py,
people.py): only their own pixels, the floor showing between their legs and around them, scaled
by their distance and placed by their bearing, standing on the floor. Any other target (and a
person in the simple world, world.flat_world) is a billboard: a cut-out of a real photo
(scikit-image samples) drawn the same way, its whole rectangle. Obstacles are drawn as boxes of
their own height, grey (solid), near-black (dark), bright steel (mirror) or faintly tinted over
what is behind them (glass); the floor beyond a drop-off is a little darker (simworld/floor.py
finds its pixels). Walls are quads in perspective (simworld/walls.py), in front of the floor,
hiding whatever is farther in each pixel (glass ones tint it).
Nearer things are drawn over farther ones. The camera stands at the robot's centre,
``height_m`` above the floor, and looks ``mount_yaw_deg`` counter-clockwise from the robot's +x
(0 the front camera, 180 the rear one), with square pixels and the configured horizontal field
of view. Anything behind a camera is not drawn: a person behind the robot is in the rear
camera's image alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image, load_sample
from simworld.body import Silhouette
from simworld.floor import drop_scale
from simworld.people import body_silhouette, stamp
from simworld.walls import (
    GLASS_ALPHA,
    GLASS_BGR,
    Floats,
    WallView,
    floor_z,
    in_front,
    tint_glass,
    wall_view,
)
from simworld.world import Material, World

# Crops (x1, y1, x2, y2) of the scikit-image photos, around the object each one shows.
SPRITES: dict[str, tuple[str, tuple[int, int, int, int]]] = {
    "person": ("cameraman", (0, 65, 330, 512)),
    "cat": ("chelsea", (0, 0, 395, 300)),
    "cup": ("coffee", (172, 17, 406, 296)),
    "motorcycle": ("motorcycle", (83, 28, 689, 454)),
}


# The default obstacle is a low box (a bin, a crate): tall enough for the laser, low enough
# that a person behind one stays in view. Each obstacle has its own height (world.Obstacle).
OBSTACLE_HEIGHT_M = 0.5
OBSTACLE_BGR = (90, 90, 95)
#: A dark obstacle's colour: below sim.depth_dark_level (30), as black plastic or rubber is.
DARK_BGR = (14, 14, 16)
#: A mirror obstacle: bright steel, well apart from the grey solid one and the near-black one.
MIRROR_BGR = (205, 200, 196)
#: The colour of an obstacle's box by its material (a solid one's is OBSTACLE_BGR).
MATERIAL_BGR = {Material.DARK: DARK_BGR, Material.MIRROR: MIRROR_BGR}
# A glass obstacle (or wall) is GLASS_ALPHA of a pale blue-green tint GLASS_BGR over what is
# behind it (simworld/walls.py holds both).
#: The lower floor beyond a drop-off is drawn this much as bright as the upper floor: in shadow
#: but still well above sim.depth_dark_level, so its depth is not lost to dark dropout.
DROP_SHADE = 0.8
#: Nothing nearer the camera than this (its centre) is drawn.
NEAREST_DRAWN_M = 0.3


@dataclass(frozen=True, slots=True)
class CameraSpec:
    width: int = 640
    height: int = 480
    hfov_deg: float = 60.0
    height_m: float = 0.6
    mount_yaw_deg: float = 0.0

    @property
    def focal_px(self) -> float:
        return (self.width / 2) / math.tan(math.radians(self.hfov_deg) / 2)


@cache
def sprite(name: str, mirror: bool = False) -> Image:
    """The cut-out for a sprite name, as BGR (mirrored left-right when asked)."""
    sample, (x1, y1, x2, y2) = SPRITES[name]
    crop = np.ascontiguousarray(load_sample(sample)[y1:y2, x1:x2])
    return np.ascontiguousarray(crop[:, ::-1]) if mirror else crop


@cache
def background(spec: CameraSpec) -> Image:
    """A wall above the horizon and a floor below it, shaded so the scene is not flat."""
    img = np.empty((spec.height, spec.width, 3), np.uint8)
    horizon = spec.height // 2
    wall = np.linspace(215, 180, horizon)[:, None]
    floor = np.linspace(120, 165, spec.height - horizon)[:, None]
    img[:horizon] = np.repeat(wall, spec.width, 1)[..., None] * np.array([1.0, 0.97, 0.9])
    img[horizon:] = np.repeat(floor, spec.width, 1)[..., None] * np.array([0.8, 0.9, 1.0])
    return img


@cache
def _shaded_background(spec: CameraSpec) -> Image:
    """The background as the lower floor beyond a drop-off is drawn: :data:`DROP_SHADE` of it."""
    out = (background(spec) * DROP_SHADE).astype(np.uint8)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True)
class Placed:
    """One thing as a camera draws it: ``target`` its index in ``world.targets`` (None: an
    obstacle, ``obstacle`` its index), ``z`` its centre's distance ahead of the camera and
    ``lateral`` to the camera's left (metres), ``radius`` its footprint's, ``height_m`` its
    height, and ``rect`` (x0, y0, x1, y1, end-exclusive) the pixels it covers, clipped to the
    image (None: not drawn at all). ``full`` is its whole unclipped rectangle, same convention.
    ``img`` is its cut-out (None for an obstacle's box); ``material`` what its surface is
    (a target's is solid). ``body``: a person with a body (world.Target's ``body``) drawn as
    this silhouette (``full`` its canvas's rectangle, ``img`` its colour); None: a flat
    cut-out or an obstacle."""

    target: int | None
    obstacle: int | None
    z: float
    lateral: float
    radius: float
    height_m: float
    rect: tuple[int, int, int, int] | None
    full: tuple[int, int, int, int]
    img: Image | None
    material: Material = Material.SOLID
    body: Silhouette | None = None


def layout(world: World, spec: CameraSpec) -> list[Placed]:
    """What ``spec``'s camera draws of ``world``, in drawing order: farthest first, each drawn
    over what came before. Anything nearer than :data:`NEAREST_DRAWN_M` (or behind) is left out.
    The one geometry the colour image (:func:`render`) and the depth image
    (simworld/depth.py) are both drawn from."""
    r = world.robot
    heading = r.theta + math.radians(spec.mount_yaw_deg)  # where the camera looks, world frame
    c, s = math.cos(heading), math.sin(heading)
    f, cx, cy = spec.focal_px, spec.width / 2, spec.height / 2
    items: list[tuple[float, float, int | None, int | None, float, float, float, Material]] = []
    bodies: dict[int, Silhouette] = {}
    for i, (tg, (tx, ty)) in enumerate(zip(world.targets, world.target_positions(), strict=True)):
        z, lateral = _to_camera(tx - r.x, ty - r.y, c, s)
        if tg.body is None:
            cut = sprite(tg.sprite, tg.mirror)
            w_m = tg.height_m * cut.shape[1] / cut.shape[0]
        else:
            bodies[i] = body_silhouette(world, i, heading)
            w_m = bodies[i].alpha.shape[1] / bodies[i].px_per_m
        items.append((z, lateral, i, None, tg.radius, tg.height_m, w_m, Material.SOLID))
    for j, ob in enumerate(world.obstacles):
        z, lateral = _to_camera(ob.x - r.x, ob.y - r.y, c, s)
        items.append((z, lateral, None, j, ob.radius, ob.height_m, 2 * ob.radius, ob.material))
    out = []
    for z, lateral, ti, oi, radius, h_m, w_m, material in sorted(items, key=lambda it: -it[0]):
        if z < NEAREST_DRAWN_M:
            continue  # behind the camera or too close to render
        u = cx - f * lateral / z
        bottom = cy + f * spec.height_m / z
        hp, wp = f * h_m / z, f * w_m / z
        img: Image | None = None
        sil: Silhouette | None = None if ti is None else bodies.get(ti)
        if ti is None:
            # A filled box from corner to corner, both included (as cv2.rectangle fills).
            x0, x1 = round(u - wp / 2), round(u + wp / 2) + 1
            y0, y1 = round(bottom - hp), round(bottom) + 1
            drawn = True
        else:
            tg = world.targets[ti]
            img = sprite(tg.sprite, tg.mirror) if sil is None else sil.colour
            w, h = round(wp), round(hp)
            left = wp / 2 if sil is None else sil.axis_px * f / z / sil.px_per_m
            x0, y0 = round(u - left), round(bottom - hp)
            x1, y1 = x0 + w, y0 + h
            drawn = 2 <= w <= 8 * spec.width and 2 <= h <= 8 * spec.height
        cx0, cy0 = max(x0, 0), max(y0, 0)
        cx1, cy1 = min(x1, spec.width), min(y1, spec.height)
        rect = (cx0, cy0, cx1, cy1) if drawn and cx1 > cx0 and cy1 > cy0 else None
        full = (x0, y0, x1, y1)
        out.append(Placed(ti, oi, z, lateral, radius, h_m, rect, full, img, material, sil))
    return out


def render(world: World, spec: CameraSpec) -> Image:
    """The image of ``world`` from a camera on the robot (its pose, plus the mounting yaw).
    Walls (simworld/walls.py) are drawn in front of the floor, and every other thing only
    where it is nearer than a wall; a glass wall tints what is behind it."""
    canvas = background(spec).copy()
    scale = drop_scale(world, spec)
    if scale is not None:
        # cv2's masked copy: numpy's (copyto with where=, boolean indexing) took ~3 ms here.
        cv2.copyTo(_shaded_background(spec), (scale > 1.0).view(np.uint8), canvas)
    view = wall_view(world, spec)
    scene_z = None
    if view is not None:
        cv2.copyTo(view.colour, view.opaque.view(np.uint8), canvas)
        scene_z = np.minimum(floor_z(spec) if scale is None else floor_z(spec) * scale, view.z)
    for p in layout(world, spec):
        if p.rect is not None:
            _draw(canvas, p, view, scene_z)
    if view is not None and scene_z is not None:
        tint_glass(canvas, view, scene_z)
    return canvas


def _draw(canvas: Image, p: Placed, view: WallView | None, scene_z: Floats | None) -> None:
    """Draw one placed thing on ``canvas`` where it is nearer than the walls (``view``; None:
    everywhere), lowering ``scene_z`` (the depth each pixel shows) where it is drawn."""
    assert p.rect is not None
    cx0, cy0, cx1, cy1 = p.rect
    view_px = canvas[cy0:cy1, cx0:cx1]
    st = None if p.body is None else stamp(p.body, p.full, p.rect)
    z: float | Floats = p.z - p.radius if st is None else np.float32(p.z) + st.dz
    shown = in_front(view, p.rect, z)
    if st is not None:
        alpha = st.alpha if shown is None else st.alpha * shown.view(np.uint8)
        cv2.copyTo(st.colour, alpha, view_px)
        shown = alpha > 0 if shown is not None else None
    elif p.img is None and p.material == Material.GLASS:
        patch = view_px.astype(np.float32)
        tint = np.array(GLASS_BGR, np.float32)
        _put(view_px, (patch + GLASS_ALPHA * (tint - patch)).astype(np.uint8), shown)
    elif p.img is None:
        _put(view_px, np.array(MATERIAL_BGR.get(p.material, OBSTACLE_BGR), np.uint8), shown)
    else:
        x0, y0, x1, y1 = p.full
        w, h = x1 - x0, y1 - y0
        inter = cv2.INTER_AREA if w < p.img.shape[1] else cv2.INTER_LINEAR
        scaled = cv2.resize(p.img, (w, h), interpolation=inter)
        _put(view_px, scaled[cy0 - y0 : cy1 - y0, cx0 - x0 : cx1 - x0], shown)
    if scene_z is not None and shown is not None:
        zs = scene_z[cy0:cy1, cx0:cx1]
        zs[shown] = np.broadcast_to(np.asarray(z, np.float32), zs.shape)[shown]


def _put(dst: Image, src: npt.NDArray[Any], where: npt.NDArray[np.bool_] | None) -> None:
    """``dst[...] = src`` (an image of ``dst``'s shape, or one colour), only ``where`` (None:
    everywhere)."""
    if where is None:
        dst[...] = src
    else:
        dst[where] = np.broadcast_to(src, dst.shape)[where]


def _to_camera(dx: float, dy: float, c: float, s: float) -> tuple[float, float]:
    """World offset -> (forward depth, lateral left) in the camera's frame (cos and sin of
    the direction it looks in)."""
    return dx * c + dy * s, -dx * s + dy * c
