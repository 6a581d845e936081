"""A person's body as a camera sees it: its silhouette, colour and front surface. Pure.

A :class:`Body` describes one person: height, shoulder width, front-to-back thickness, the
colours of their clothes and skin, where they face and how long their stride is. From it
:func:`simworld.body_draw.silhouette` draws, for a yaw relative to the camera and a phase of
the walk, the person as the camera sees them at a canonical scale (:data:`CANON_PX` pixels
tall): which pixels are the person (head, neck, torso, two arms with hands, two legs with feet,
the floor visible between the legs and around them), their colour (each part in its clothes,
shaded by how its surface turns from the camera) and the depth of the front surface at each
pixel relative to the body's axis (metres along the camera's optical axis; negative: nearer).
simworld/render.py scales it by the person's distance as it did the flat photo cut-out, and
simworld/depth.py adds the person's z to the depth offsets (simworld/body_draw.py draws it,
simworld/people.py finds the pose and scales it).

The model (metres, the person's own frame: ``a`` to their left, ``b`` forward, ``y`` up from
the floor, on their vertical axis at the target's position):

- the torso an elliptic cylinder from the hips to the shoulders, ``shoulder_m`` wide at the
  shoulders (narrower at the waist), ``depth_m`` thick; seen from any yaw its front surface is
  the rotated ellipse's, so the depth grows towards its sides as a real chest's does, and a
  person side-on is ``depth_m`` wide, not ``shoulder_m``;
- the head an ellipsoid a little ahead of the chest, the neck a short cylinder;
- arms and legs tapered capsules from the shoulders and hips; walking, they swing forward and
  back with the phase (legs opposite each other, each arm opposite its leg), so side-on the
  legs open a gap the floor shows through, and front-on a gap stays between them.

The projection is weak perspective: the body is drawn at its axis's distance (its size in the
image), with depth offsets along the optical axis; a person's own depth is a few tenths of a
metre, so the error is that of a flat scale across that depth, under 4 % of the offsets.
"""

from __future__ import annotations

import itertools
import math
import zlib
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from common.images import Image

Floats = npt.NDArray[np.float32]
BGR = tuple[int, int, int]

#: The canonical silhouette's height in pixels (the person's whole height); the renderer
#: resizes it to the person's size in each image, as it did the photo cut-out.
CANON_PX = 360
#: A silhouette is drawn for yaws rounded to this many degrees and for this many phases of a
#: stride (a cached silhouette per rounded pose: :func:`silhouette`).
YAW_STEP_DEG = 15.0
PHASES = 12
#: How far each leg swings from the vertical at the walk's extremes, and each arm.
LEG_SWING_DEG = 22.0
ARM_SWING_DEG = 16.0
#: A target moving slower than this (m/s) stands: its legs stop swinging.
WALKING_MPS = 0.05
#: How many canonical silhouettes are kept (each a few hundred kB).
CACHE_SIZE = 128

#: The clothes a person may wear, (top, trousers): BGR. The dark ones' grey level is under
#: sim.depth_dark_level (30), so a stereo depth camera loses much of them (simworld/depth.py
#: apply's dark dropout), as it does real black cloth.
CLOTHES: tuple[tuple[BGR, BGR], ...] = (
    ((18, 18, 20), (22, 20, 20)),  # all in black: little depth on most of the body
    ((150, 90, 40), (60, 50, 45)),  # blue shirt, dark grey trousers
    ((40, 40, 170), (120, 85, 50)),  # red top, jeans
    ((200, 200, 205), (20, 20, 24)),  # white shirt, black trousers
    ((60, 110, 70), (150, 160, 170)),  # green top, light trousers
    ((20, 22, 25), (130, 95, 60)),  # black coat, jeans
    ((170, 150, 140), (90, 80, 75)),  # light grey top, grey trousers
)
SKINS: tuple[BGR, ...] = ((150, 175, 215), (105, 135, 180), (70, 95, 140), (175, 195, 230))
HAIRS: tuple[BGR, ...] = ((25, 30, 35), (40, 60, 90), (90, 120, 150), (140, 140, 140))
SHOES: BGR = (35, 35, 38)


@dataclass(frozen=True, slots=True)
class Body:
    """One person's build, clothes and stance (metres, BGR colours).

    ``facing_deg``: the world yaw they face (counter-clockwise from the world's +x); None:
    the way they walk while they walk, and towards the robot while they stand.
    ``stride_m``: the length of a whole gait cycle (two steps).
    """

    height_m: float = 1.75
    shoulder_m: float = 0.46
    depth_m: float = 0.26
    top: BGR = (150, 90, 40)
    trousers: BGR = (60, 50, 45)
    skin: BGR = (150, 175, 215)
    hair: BGR = (25, 30, 35)
    facing_deg: float | None = None
    stride_m: float = 1.4

    def dark_parts(self, level: int) -> tuple[str, ...]:
        """The parts whose clothes' grey level is under ``level`` (0..255): those a stereo
        camera's dark dropout thins out."""
        parts = {"top": self.top, "trousers": self.trousers, "skin": self.skin}
        return tuple(k for k, c in parts.items() if _grey(c) < level)


def _grey(bgr: BGR) -> float:
    b, g, r = bgr
    return 0.114 * b + 0.587 * g + 0.299 * r  # as cv2.COLOR_BGR2GRAY weighs them


def body_for(key: str | int, seed: int = 0) -> Body:
    """A person of their own look, the same every time for the same ``key`` (an id) and
    ``seed``: height 1.5-1.95 m, shoulders and thickness in proportion with some spread, one
    of :data:`CLOTHES`, a skin and a hair colour."""
    rng = np.random.default_rng([zlib.crc32(str(key).encode()), seed])
    height = float(rng.uniform(1.5, 1.95))
    build = float(rng.uniform(0.88, 1.15))  # slim .. broad
    top, trousers = CLOTHES[int(rng.integers(len(CLOTHES)))]
    return Body(
        height_m=round(height, 3),
        shoulder_m=round(0.26 * height * build, 3),
        depth_m=round(0.15 * height * build, 3),
        top=top,
        trousers=trousers,
        skin=SKINS[int(rng.integers(len(SKINS)))],
        hair=HAIRS[int(rng.integers(len(HAIRS)))],
        stride_m=round(0.8 * height, 3),
    )


def people(n: int, seed: int = 0) -> list[Body]:
    """``n`` different people, deterministic from ``seed``."""
    return [body_for(i, seed) for i in range(n)]


def walked_m(path: tuple[tuple[float, float, float], ...], loop: bool, t: float) -> float:
    """How far a target on ``path`` (world.Target's (t, x, y) waypoints) has walked by ``t``."""
    pairs = list(itertools.pairwise(path))
    lengths = [math.hypot(x1 - x0, y1 - y0) for (_, x0, y0), (_, x1, y1) in pairs]
    t0, t_end = path[0][0], path[-1][0]
    laps = 0.0
    if loop and t > t0 and t_end > t0:
        laps, t = divmod(t - t0, t_end - t0)
        t += t0
    done = laps * sum(lengths)
    for ((ta, _, _), (tb, _, _)), seg in zip(pairs, lengths, strict=True):
        if t >= tb:
            done += seg
        elif t > ta:
            done += seg * (t - ta) / (tb - ta)
    return done


def pose_key(yaw_deg: float, phase: float | None) -> tuple[float, int | None]:
    """A pose rounded to the silhouettes drawn: yaw (degrees, -180 < yaw <= 180) to
    :data:`YAW_STEP_DEG`, phase (0..1, None: standing) to one of :data:`PHASES`."""
    yaw = (round(yaw_deg / YAW_STEP_DEG) * YAW_STEP_DEG + 180.0) % 360.0 - 180.0
    return (180.0 if yaw == -180.0 else yaw), None if phase is None else int(
        phase * PHASES
    ) % PHASES


@dataclass(frozen=True, slots=True, eq=False)
class Silhouette:
    """A body drawn at the canonical scale: ``alpha`` (h, w) 255 on the person, 0 elsewhere;
    ``colour`` (h, w, 3) BGR; ``dz`` (h, w) the front surface's offset from the body's axis
    along the optical axis (metres, negative nearer; 0 off the person). ``px_per_m`` its
    scale, ``axis_px`` the column of the body's axis (a float, pixel edges at integers); the
    rows run from the top of the head (row 0) to the floor (the bottom edge). ``truth_dz``:
    the front surface's offset on the axis at half the person's height (the truth a depth
    camera is held to). ``area``: the person's pixels. Read-only arrays; compared by
    identity (it is cached)."""

    alpha: Image
    colour: Image
    dz: Floats
    px_per_m: float
    axis_px: float
    truth_dz: float
    area: int


def shade(colour: BGR, nz: Floats) -> Image:
    """``colour`` lit by how squarely the surface faces the camera (``nz`` 0..1): the rim of a
    round thing is darker than its middle."""
    light = (0.55 + 0.45 * nz)[..., None]
    out: Image = np.clip(np.array(colour, np.float32) * light, 0, 255).astype(np.uint8)
    return out


def cloth(px_per_m: float, shape: tuple[int, int]) -> Floats:
    """How cloth's folds light it, per pixel of a canvas ``shape`` at ``px_per_m``: the
    cameraman's coat (scikit-image's sample photo, the simulator's old cut-out), its light
    around 1, tiled :data:`CLOTH_M` metres to a tile."""
    return _cloth(round(px_per_m * CLOTH_M), shape)


#: The coat's crop of the cameraman photo (x0, y0, x1, y1), the metres one tile spans, and
#: how much of its light's variation shows.
COAT_CROP = (10, 245, 130, 505)
CLOTH_M = 0.3
CLOTH_CONTRAST = 0.6


@lru_cache(maxsize=8)
def _cloth(tile_px: int, shape: tuple[int, int]) -> Floats:
    from common.images import load_sample

    x0, y0, x1, y1 = COAT_CROP
    grey = load_sample("cameraman")[y0:y1, x0:x1, 0].astype(np.float32)
    tile = cv2.resize(grey, (tile_px, round(tile_px * grey.shape[0] / grey.shape[1])))
    light = 1.0 + CLOTH_CONTRAST * (tile - tile.mean()) / tile.mean()
    reps = (shape[0] // light.shape[0] + 1, shape[1] // light.shape[1] + 1)
    out: Floats = np.clip(np.tile(light, reps)[: shape[0], : shape[1]], 0.3, 1.8)
    out.setflags(write=False)
    return out


def coat(size: tuple[int, int]) -> Floats:
    """The light of a real coat's front (the cameraman's: lapels, buttons, folds), ``size``
    (w, h), around 1: a torso's clothes as the detector knows clothes."""
    x0, y0, x1, y1 = COAT_FRONT
    grey = _grey_sample()[y0:y1, x0:x1]
    tile = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
    out: Floats = np.clip(1.0 + COAT_CONTRAST * (tile - tile.mean()) / tile.mean(), 0.3, 1.8)
    return out


#: The coat's front in the cameraman photo (x0, y0, x1, y1), and how much of its light shows.
COAT_FRONT = (0, 150, 250, 512)
COAT_CONTRAST = 0.5


@lru_cache(maxsize=1)
def _grey_sample() -> Floats:
    from common.images import load_sample

    out: Floats = load_sample("cameraman")[..., 0].astype(np.float32)
    out.setflags(write=False)
    return out


def face_texture(size: tuple[int, int], skin: BGR) -> Image:
    """A real face and its hair (scikit-image's astronaut photo), ``size`` (w, h), its skin
    tinted towards ``skin``: the detector knows a person by their face and hair far better
    than by a shaded shape."""
    face = cv2.resize(_face(), size, interpolation=cv2.INTER_AREA).astype(np.float32)
    tint = np.array(skin, np.float32) / np.array(FACE_SKIN, np.float32)
    out: Image = np.clip(face * tint, 0, 255).astype(np.uint8)
    return out


#: The photo's face, and its skin's colour (BGR): the tint's reference.
FACE_CROP = (165, 25, 290, 190)
FACE_SKIN: BGR = (150, 175, 215)


@lru_cache(maxsize=1)
def _face() -> Image:
    from common.images import load_sample

    x0, y0, x1, y1 = FACE_CROP
    return np.ascontiguousarray(load_sample("astronaut")[y0:y1, x0:x1])
